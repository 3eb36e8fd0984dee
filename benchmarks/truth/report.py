"""Outputs of a run: the raw JSON, a markdown summary, a time-against-error plot."""

from __future__ import annotations

import json
import math
import statistics
from collections.abc import Callable, Iterable
from pathlib import Path

GROUPS = (("core", "Core: 8-bit, 7 frames 2 EV apart, every scene x every curve"),
          ("ladder", "Ladders: 8-bit, the other 11 ladders (3/5/7/9 frames x 1/2/3 EV)"),
          ("jpeg", "JPEG: 8-bit through JPEG quality 90 (4:2:0), 7 frames 2 EV apart"),
          ("16-bit", "16-bit, 7 frames 2 EV apart (OpenCV and colour-hdri take 8-bit only: "
                     "hdrio alone)"),
          ("linear", "Linear 16-bit (a linear TIFF), 7 frames 2 EV apart: hdrio alone"),
          ("camera", "Camera-like: raw clip, white balance and a real camera's colour matrix "
                     "(4 cameras x 2 noise levels), EMoR mean curve, 7 frames 2 EV apart"))
DEFAULT = "hdrio default"
NOISE_ORACLE = "oracle noise-aware"
CLIP_ORACLE = "oracle (clipped observations)"


def ok_rows(rows: Iterable[dict], **where: object) -> list[dict]:
    return [r for r in rows if r.get("status") == "ok"
            and all(r.get(k) == v for k, v in where.items())]


def _values(rows: list[dict], get: Callable[[dict], object]) -> list[float]:
    values = [get(r) for r in rows]
    return [float(v) for v in values if isinstance(v, (int, float)) and math.isfinite(v)]


def _median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


def summarise(rows: list[dict], method: str) -> dict[str, object]:
    """One method's summary over ``rows`` (medians over stacks unless stated)."""
    mine = ok_rows(rows, method=method)
    p99 = _values(mine, lambda r: r["well"]["p99"])
    peaks = _values(mine, lambda r: r.get("peak_mb"))
    return {
        "stacks": len(mine),
        "errors": sum(1 for r in rows if r["method"] == method and r["status"] != "ok"),
        "median": _median(_values(mine, lambda r: r["well"]["median"])),
        "p99_max": max(p99) if p99 else None,
        "luminance": _median(_values(mine, lambda r: r.get("luminance_median"))),
        "clipped": _median(_values(mine, lambda r: r["clipped"]["median"])),
        "black": _median(_values(mine, lambda r: r["black"]["median"])),
        "other": _median(_values(mine, lambda r: r["other"]["median"])),
        "response": _median(_values(mine, lambda r: r.get("response_rms_stops"))),
        "bad_pixels": sum(int(r["nonfinite"]) + int(r["nonpositive"]) for r in mine),
        "bad_well": sum(int(r["bad_pixels"]["well"]) for r in mine),
        "time": _median(_values(mine, lambda r: r.get("time_s"))),
        "peak_mb": max(peaks) if peaks else None,
    }


def head_to_head(rows: list[dict], peers: list[str]) -> dict[str, object] | None:
    """hdrio default against the best peer on each stack where both ran."""
    wins = {"median": 0, "p99": 0}
    gaps: dict[str, list[tuple[float, str, str]]] = {"median": [], "p99": []}
    stacks = 0
    for key in dict.fromkeys(r["stack"] for r in rows):
        ours = ok_rows(rows, stack=key, method=DEFAULT)
        theirs = [r for r in ok_rows(rows, stack=key) if r["method"] in peers]
        if not ours or not theirs:
            continue
        stacks += 1
        for metric in wins:
            best = min(theirs, key=lambda r: r["well"][metric])
            gap = ours[0]["well"][metric] - best["well"][metric]
            wins[metric] += gap <= 0
            gaps[metric].append((gap, key, best["method"]))
    if not stacks:
        return None
    return {"stacks": stacks, "wins": wins,
            "median_gap": {m: statistics.median(g for g, _, _ in v) for m, v in gaps.items()},
            "worst": {m: max(v) for m, v in gaps.items()}}


def region_shares(rows: list[dict]) -> str:
    """One line: how the stacks' pixels split into the scored regions."""
    first = {r["stack"]: r["pixels"] for r in ok_rows(rows)}
    totals = {name: sum(p[name] for p in first.values()) for name in
              ("well", "clipped", "black", "other")}
    total = max(1, sum(totals.values()))
    shares = ", ".join(f"{name} {100 * count / total:.1f} %" for name, count in totals.items())
    return f"{len(first)} stacks, {total / 1e6:.2f} Mpx: {shares}."


def _pct(v: object) -> str:
    return f"{100 * v:.2f}" if isinstance(v, float) else "–"


def _num(v: object, digits: int = 3) -> str:
    return f"{v:.{digits}g}" if isinstance(v, float) else "–"


def summary_table(rows: list[dict], methods: list[str]) -> list[str]:
    lines = ["| method | stacks | median err % | max p99 % | lum. median % | clipped "
             "median % | black median % | other median % | response RMS (stops) | non-finite "
             "or ≤0 px (well-exposed) | median time (s) | max peak MB |", "|" + "---|" * 12]
    for name in methods:
        s = summarise(rows, name)
        if not s["stacks"] and not s["errors"]:
            continue
        stacks = f"{s['stacks']}" + (f" ({s['errors']} failed)" if s["errors"] else "")
        lines.append(f"| {name} | {stacks} | {_pct(s['median'])} | {_pct(s['p99_max'])} | "
                     f"{_pct(s['luminance'])} | {_pct(s['clipped'])} | {_pct(s['black'])} | "
                     f"{_pct(s['other'])} | "
                     f"{_num(s['response'], 2)} | {s['bad_pixels']} ({s['bad_well']}) | "
                     f"{_num(s['time'])} | "
                     f"{_num(s['peak_mb'], 3)} |")
    return lines


def breakdown(rows: list[dict], methods: list[str], by: str) -> list[str]:
    """Median error (%) of each method, one row per value of ``by``."""
    keys = list(dict.fromkeys(str(r[by]) for r in rows))
    present = [m for m in methods if ok_rows(rows, method=m)]
    lines = [f"| {by} | " + " | ".join(present) + " |", "|" + "---|" * (len(present) + 1)]
    for key in keys:
        cells = [_pct(_median(_values([r for r in ok_rows(rows, method=m) if str(r[by]) == key],
                                      lambda r: r["well"]["median"]))) for m in present]
        lines.append(f"| {key} | " + " | ".join(cells) + " |")
    return lines


def full_run(rows: list[dict], methods: list[str], peers: list[str]) -> list[str]:
    """Every method over all the stacks every peer ran on: the run's headline numbers.

    Per-stack medians and 99th percentiles of the well-exposed error, summarised over the
    stacks by their median, their mean and their worst (max).
    """
    stacks = {r["stack"] for r in ok_rows(rows)}
    for peer in peers:
        stacks &= {r["stack"] for r in ok_rows(rows, method=peer)}
    if not stacks:
        return []
    lines = [f"### Full run: the {len(stacks)} stacks every peer ran on", "",
             "| method | median err % | median p99 % | mean p99 % | max p99 % |",
             "|---|---|---|---|---|"]
    for method in methods:
        chosen = [r for r in ok_rows(rows, method=method) if r["stack"] in stacks]
        if len(chosen) != len(stacks):
            continue
        medians = _values(chosen, lambda r: r["well"]["median"])
        p99s = _values(chosen, lambda r: r["well"]["p99"])
        if not p99s:
            continue
        lines.append(f"| {method} | {_pct(_median(medians))} | {_pct(_median(p99s))} | "
                     f"{_pct(sum(p99s) / len(p99s))} | {_pct(max(p99s))} |")
    return lines + [""]


def oracle_ratios(rows: list[dict], methods: list[str], reference: str) -> list[str]:
    """Each method's error over ``reference``'s (the noise-aware oracle), per group.

    Per group: the ratio of the means over stacks of the per-stack median and p99 (the
    issue's measure), and the worst single stack's ratio of each.
    """
    lines = [f"### Ratio to the {reference}", "",
             "Mean over stacks of the per-stack median (p99) error, divided by the oracle's; "
             "*worst* is the largest per-stack ratio.", "",
             "| group | method | stacks | median ratio | p99 ratio | worst median ratio | "
             "worst p99 ratio |", "|---|---|---|---|---|---|---|"]
    groups = [g for g, _ in GROUPS if any(r["group"] == g for r in rows)] + ["all"]
    for group in groups:
        subset = [r for r in rows if group == "all" or r["group"] == group]
        oracle = {r["stack"]: r["well"] for r in ok_rows(subset, method=reference)}
        for method in methods:
            if method == reference:
                continue
            mine = [r for r in ok_rows(subset, method=method) if r["stack"] in oracle
                    and isinstance(r["well"]["median"], float)]
            if not mine:
                continue
            ratio = {}
            for metric in ("median", "p99"):
                ours = [r["well"][metric] for r in mine]
                theirs = [oracle[r["stack"]][metric] for r in mine]
                ratio[metric] = (sum(ours) / sum(theirs),
                                 max(a / b for a, b in zip(ours, theirs) if b > 0))
            lines.append(f"| {group} | {method} | {len(mine)} | {ratio['median'][0]:.3f} | "
                         f"{ratio['p99'][0]:.3f} | {ratio['median'][1]:.2f} | "
                         f"{ratio['p99'][1]:.2f} |")
    return lines + [""]


def transition_table(rows: list[dict], methods: list[str]) -> list[str]:
    """Camera-like stacks: each method's hue error on clip-transition pixels against the
    clipped-observation oracle's, stack by stack (:mod:`benchmarks.truth.camera`)."""
    oracle = {r["stack"]: r["transition"] for r in ok_rows(rows, method=CLIP_ORACLE)
              if r.get("transition", {}).get("hue_p99")}
    lines = ["Hue angle error (degrees) on clip-transition pixels; *ratio*: a stack's p99 "
             f"over the {CLIP_ORACLE}'s on the same stack.", "",
             "| method | stacks | median p99 | max p99 | median ratio | max ratio | "
             "radiance median % |", "|---|---|---|---|---|---|---|"]
    for name in methods:
        mine = [r for r in ok_rows(rows, method=name) if r["stack"] in oracle
                and r.get("transition", {}).get("hue_p99") is not None]
        if not mine:
            continue
        p99 = [r["transition"]["hue_p99"] for r in mine]
        ratios = [r["transition"]["hue_p99"] / oracle[r["stack"]]["hue_p99"] for r in mine]
        median = _median(_values(mine, lambda r: r["transition"]["median"]))
        lines.append(f"| {name} | {len(mine)} | {statistics.median(p99):.2f} | "
                     f"{max(p99):.2f} | {statistics.median(ratios):.2f} | {max(ratios):.2f} | "
                     f"{_pct(median)} |")
    return lines + [""]


def markdown(results: dict, command: str = "python -m benchmarks.truth") -> str:
    rows, env, config = results["rows"], results["environment"], results["config"]
    methods = [m["name"] for m in results["methods"]]
    peers = [m["name"] for m in results["methods"] if m["kind"] == "peer"]
    for r in ok_rows(rows):
        r["ladder"] = f"{r['frames']} x {r['ev']:g} EV"
    versions = ", ".join(f"{k} {v}" for k, v in env["versions"].items())
    out = [f"Command: `{command}` — {config['name']} run, {config['stacks']} stacks, scenes "
           f"at ~{config['width'] or 'full'} px wide, {config['repeats']} timed repeat(s); "
           f"wall time {results['wall_time_s']:.0f} s on {env['cpu_available']} CPU(s) "
           f"({env['cpu_model']}), {env['date']}, commit {str(env['git_commit'])[:10]}"
           + (" (hdrio/ modified)" if env.get("hdrio_dirty") else "") + ".", "",
           f"Versions: {versions}.", ""]
    out += [f"Note: {note}." for note in results.get("notes", [])]
    out += ["Errors are relative, after one best global scale fitted on the well-exposed "
            "pixels: *median err* is the median over stacks of each stack's median, *max "
            "p99* the worst stack's 99th percentile; clipped, black and other (see "
            "docs/accuracy.md) use the same scale. "
            "*oracle (true response)* is hdrio's default merge given the true response; "
            f"*{NOISE_ORACLE}* adds the true noise model (the bound); *oracle Poisson* is "
            "the Poisson estimator with the true response (references, not methods).",
            ""]
    out += full_run(rows, methods, peers)
    if any(r["method"] == NOISE_ORACLE for r in ok_rows(rows)):
        out += oracle_ratios(rows, methods, NOISE_ORACLE)
    for group, title in GROUPS:
        subset = [r for r in rows if r["group"] == group]
        if not subset:
            continue
        out += [f"### {title}", "", region_shares(subset), ""]
        out += summary_table(subset, methods) + [""]
        if group == "camera":
            out += transition_table(subset, methods)
        match = head_to_head(subset, peers)
        if match:
            worst = match["worst"]
            out += [f"hdrio default vs the best peer on each stack: better or equal on "
                    f"{match['wins']['median']}/{match['stacks']} stacks for the median, "
                    f"{match['wins']['p99']}/{match['stacks']} for p99; median gap "
                    f"{_pct(match['median_gap']['median'])} / {_pct(match['median_gap']['p99'])}"
                    f" points; worst {_pct(worst['median'][0])} points ({worst['median'][1]}, "
                    f"{worst['median'][2]}) / {_pct(worst['p99'][0])} points ({worst['p99'][1]}"
                    f", {worst['p99'][2]}).", ""]
    core = [r for r in rows if r["group"] == "core"]
    for by in ("curve", "scene"):
        if core:
            out += [f"Median error (%) by {by}, 8-bit core stacks:", ""]
            out += breakdown(core, methods, by) + [""]
    ladder = [r for r in rows if r["group"] in ("ladder", "core")
              and r["scene"] in {x["scene"] for x in rows if x["group"] == "ladder"}
              and r["curve"] in {x["curve"] for x in rows if x["group"] == "ladder"}]
    if any(r["group"] == "ladder" for r in ladder):
        out += ["Median error (%) by ladder, ladder scenes and curves:", ""]
        out += breakdown(ladder, methods, "ladder") + [""]
    return "\n".join(out)


def pareto(points: dict[str, tuple[float, float]]) -> list[str]:
    """Names not dominated in (time, error), both minimised, in increasing time."""
    front, best = [], math.inf
    for name, (_t, e) in sorted(points.items(), key=lambda kv: (kv[1][0], kv[1][1])):
        if e < best:
            front.append(name)
            best = e
    return front


def plot(results: dict, path: Path, group: str = "core") -> Path:
    """Median time against median error, log-log, one point per method; Pareto highlighted."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in results["rows"] if r["group"] == group] or results["rows"]
    kinds = {m["name"]: m["kind"] for m in results["methods"]}
    points = {}
    for name in kinds:
        s = summarise(rows, name)
        if s["time"] and s["median"]:
            points[name] = (s["time"], 100 * s["median"])
    front = pareto({n: p for n, p in points.items() if kinds[n] != "reference"})
    figure, axes = plt.subplots(figsize=(7.5, 4.2), dpi=100)
    colours = {"hdrio": plt.get_cmap("Blues"), "peer": plt.get_cmap("Oranges"),
               "reference": plt.get_cmap("Greys")}
    markers = "osD^vP*Xhp<>"
    counts = {kind: sum(1 for n in points if kinds[n] == kind) for kind in colours}
    seen = dict.fromkeys(colours, 0)
    for k, (name, (t, e)) in enumerate(points.items()):
        kind = kinds[name]
        seen[kind] += 1
        colour = colours[kind](0.95 - 0.5 * (seen[kind] - 1) / max(1, counts[kind] - 1))
        axes.scatter(t, e, s=70 if name in front else 40, marker=markers[k % len(markers)],
                     color=colour, edgecolors="black" if name in front else "none",
                     linewidths=1.2, zorder=3, label=name + (" *" if name in front else ""))
    if front:
        axes.plot(*zip(*(points[n] for n in front)), color="black", lw=1, ls="--",
                  zorder=2, label="Pareto front (*)")
    axes.set_xscale("log")
    axes.set_yscale("log")
    plain = matplotlib.ticker.FuncFormatter(lambda value, _: f"{value:g}")
    sparse = matplotlib.ticker.FuncFormatter(
        lambda value, _: f"{value:g}" if f"{value:.0e}"[0] in "25" else "")
    for axis in (axes.xaxis, axes.yaxis):
        axis.set_major_formatter(plain)
        axis.set_minor_formatter(sparse)
    axes.set_xlabel("median wall time per stack (s)")
    axes.set_ylabel("median relative error, well-exposed (%)")
    axes.set_title(f"Truth harness, {results['config']['name']} run, {group} stacks "
                   "(blue hdrio, orange peers, grey reference)", fontsize=9)
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    figure.tight_layout()
    figure.savefig(path)
    plt.close(figure)
    return path


def write_outputs(results: dict, folder: Path, command: str) -> dict[str, Path]:
    """``truth_<name>.json``, ``truth_<name>.md`` and ``truth_<name>.png`` in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    stem = f"truth_{results['config']['name']}"
    paths = {"json": folder / f"{stem}.json", "markdown": folder / f"{stem}.md",
             "plot": folder / f"{stem}.png"}
    paths["json"].write_text(json.dumps(results, indent=1, allow_nan=True) + "\n")
    paths["markdown"].write_text(markdown(results, command) + "\n")
    plot(results, paths["plot"])
    return paths
