"""``python -m benchmarks.cores``: the merge and a shoot on many cores (issue 30).

Every row is a command as a user runs it, in a fresh process (wall seconds, CPU seconds
of all its threads, peak resident memory, from the OS), on the first N CPUs of the
machine for each N of ``--cores`` (its affinity set before it starts, so hdrio sizes its
threads to N as under ``taskset``):

* the 7 x 24 MP JPEG merge to a half EXR against its I/O floor (a plain OpenImageIO
  script that decodes the same JPEGs and writes the same pixels), alternated, the median
  of ``--repeats``; the ratios to read are the merge's over the floor's, in wall time and
  in CPU seconds, at each N;
* the merge's peak at 5, 7 and 9 brackets (every CPU);
* one merge at each N of ``--scaling`` with its progress log: where the wall time and
  the CPU seconds go, stage by stage, as cores are added (``HDRIO_PROGRESS_CPU=1``);
* with ``--baseline TREE``, the same 7-bracket merge by the ``hdrio`` of ``TREE`` (a
  folder holding another commit's ``hdrio/`` package: ``git archive COMMIT hdrio | tar
  -x -C TREE``), alternated with the two above, so that a change is measured against
  its parent in one run on one machine (``python -m hdrio`` with ``TREE`` first on
  ``PYTHONPATH``, started in the benchmark's temporary folder: ``python -m`` puts the
  working directory first on ``sys.path``, and from the checkout it would run the
  checkout's);
* the first run with an empty kernel cache against a warm one (``hdrio demo``);
* a shoot (:mod:`benchmarks.farm`): ``--sets`` sets of 7 x 12 MP, ``--group`` with
  ``--threads`` of each count of ``--workers`` and a Dask ``LocalCluster`` of ``--dask``.

On the 16-core device (docs/speed.md, "Many cores")::

    bash .device-kit/run.sh python -m benchmarks.cores --out $OUT

Prints a table and writes ``cores.json`` (and ``farm.json``) under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import farm
from benchmarks.speed.endtoend import write_jpegs
from benchmarks.speed.process import (
    baseline_environment,
    demo_rows,
    floor_command,
    hdrio_command,
    timed,
)
from benchmarks.speed.scene import bracket_stack
from hdrio.io.images import read_image

DEFAULT_OUT = Path(__file__).parent / "results"
_STAGE = re.compile(r"^\[\s*([\d.]+) s(?:, CPU\s*([\d.]+) s)?\] (.+)$", re.MULTILINE)


def all_cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
        os.cpu_count() or 1)


_WROTE = re.compile(r"^wrote: .* in ([\d.]+) s", re.MULTILINE)


def stages(log: str, seconds: float) -> dict[str, float]:
    """Seconds of each stage of a merge's progress log (``[  1.26 s] camera response``),
    from its start to the next stage's; the write's from the summary (``wrote: ... in
    0.84 s``); and the rest of the process's ``seconds``: start-up (imports) before the
    log's clock starts, and the summary and exit after the write."""
    marks = [(float(t), label.split(" ")[0]) for t, _, label in _STAGE.findall(log)]
    written = _WROTE.search(log)
    ends = [t for t, _ in marks[1:]] + [marks[-1][0] + (float(written.group(1))
                                                       if written else 0.0)]
    result: dict[str, float] = {}
    for (start, label), end in zip(marks, ends):
        result[label] = result.get(label, 0.0) + end - start
    result["start-up and exit"] = seconds - sum(result.values())
    return result


def cpu_stages(log: str, cpu_seconds: float) -> dict[str, float]:
    """CPU seconds of each stage of a progress log written with ``HDRIO_PROGRESS_CPU=1``
    (``[  1.26 s, CPU   4.80 s] camera response``): the process's CPU before its first
    line (imports, parsing, checking the inputs), each stage's from its line to the
    next, the last one's (the write, the summary and the exit) to the process's
    ``cpu_seconds``. Empty when the log has no CPU column."""
    marks = [(float(cpu), label.split(" ")[0]) for _, cpu, label in _STAGE.findall(log)
             if cpu]
    if not marks:
        return {}
    result = {"before the first line": marks[0][0]}
    for (start, label), (end, _) in zip(marks, [*marks[1:], (cpu_seconds, "")]):
        result[label] = result.get(label, 0.0) + end - start
    return result


_METHODS = {"floor": "I/O floor (decode the 7 JPEGs, write the pixels as half EXR)",
            "merge": "hdrio merge 7 JPEGs -> half EXR",
            "baseline": "the baseline's hdrio merge 7 JPEGs -> half EXR"}


def merge_rows(paths: list[str], exposures: list[str], folder: Path, cores: list[int],
               repeats: int, env: dict[str, str], baseline: Path | None = None
               ) -> list[dict]:
    """The 7-bracket merge and its floor at each count of ``cores`` (and the
    ``baseline`` tree's merge), alternated."""
    seven = slice(1, 8)
    arguments = ["merge", *paths[seven], "--exposures", ",".join(exposures[seven]),
                 "-o", str(folder / "merge7.exr"), "-q"]
    commands = {"floor": (floor_command(paths[seven], folder / "written.npy",
                                        folder / "floor.exr"), env),
                "merge": ([*hdrio_command(), *arguments], env)}
    if baseline is not None:
        commands["baseline"] = ([sys.executable, "-m", "hdrio", *arguments],
                                {**env, **baseline_environment(baseline, folder)})
    rows = []
    for count in cores:
        runs: dict[str, list[dict]] = {name: [] for name in commands}
        for _ in range(repeats):
            for name, (argv, environment) in commands.items():
                runs[name].append(timed(argv, environment, count, cwd=folder))
        for name, found in runs.items():
            rows.append({"section": "merge 7 x 24 MP", "cores": count,
                         "method": _METHODS[name], "what": name,
                         "seconds": statistics.median(r["seconds"] for r in found),
                         "cpu_seconds": statistics.median(r["cpu_seconds"] for r in found),
                         "peak_mb": max(r["peak_mb"] for r in found),
                         "all_seconds": [round(r["seconds"], 3) for r in found]})
    return rows


def peak_rows(paths: list[str], exposures: list[str], folder: Path,
              env: dict[str, str]) -> list[dict]:
    """The merge's peak at 5 and 9 brackets (7 is in the merge rows), every CPU."""
    rows = []
    for count in (5, 9):
        first = (len(paths) - count) // 2
        chosen = slice(first, first + count)
        found = timed([*hdrio_command(), "merge", *paths[chosen], "--exposures",
                       ",".join(exposures[chosen]), "-o", str(folder / f"m{count}.exr"),
                       "-q"], env)
        rows.append({"section": "peak", "cores": all_cores(), "brackets": count,
                     "method": f"hdrio merge {count} JPEGs -> half EXR",
                     "seconds": found["seconds"], "cpu_seconds": found["cpu_seconds"],
                     "peak_mb": found["peak_mb"]})
    return rows


def scaling_rows(paths: list[str], exposures: list[str], folder: Path, cores: list[int],
                 env: dict[str, str]) -> list[dict]:
    """One 7-bracket merge at each count of ``cores`` with its stages' seconds."""
    rows = []
    for count in cores:
        found = timed([*hdrio_command(), "merge", *paths[1:8], "--exposures",
                       ",".join(exposures[1:8]), "-o", str(folder / "scaling.exr")],
                      {**env, "HDRIO_PROGRESS_CPU": "1"}, count, cwd=folder)
        rows.append({"section": "scaling", "cores": count,
                     "method": "hdrio merge 7 JPEGs, stages", "seconds": found["seconds"],
                     "cpu_seconds": found["cpu_seconds"], "peak_mb": found["peak_mb"],
                     "stages": stages(found["output"], found["seconds"]),
                     "cpu_stages": cpu_stages(found["output"], found["cpu_seconds"]),
                     "log": found["output"]})
    return rows


def ratios(rows: list[dict]) -> dict[str, float]:
    """Issue 30's ratios, each from rows of this run."""
    result = {}
    pick = {(row["section"], row.get("what"), row["cores"]): row for row in rows}
    for count in sorted({row["cores"] for row in rows if row["section"] == "merge 7 x 24 MP"}):
        floor = pick[("merge 7 x 24 MP", "floor", count)]
        for name in ("merge", "baseline"):
            merge = pick.get(("merge 7 x 24 MP", name, count))
            if merge is None:
                continue
            result[f"{count} cores: {name} / floor (wall)"] = (merge["seconds"]
                                                               / floor["seconds"])
            result[f"{count} cores: {name} / floor (CPU seconds)"] = (
                merge["cpu_seconds"] / floor["cpu_seconds"])
    peaks = [row["peak_mb"] for row in rows if row["section"] == "peak"] + [
        row["peak_mb"] for row in rows
        if row.get("what") == "merge" and row["cores"] == all_cores()]
    if len(peaks) > 1:
        result["peak MB, largest / smallest over 5..9 brackets"] = max(peaks) / min(peaks)
    demo = {row.get("demo"): row for row in rows}
    if "cold" in demo and "warm" in demo:
        result["demo: empty kernel cache / warm"] = (demo["cold"]["seconds"]
                                                      / demo["warm"]["seconds"])
    return result


def table(rows: list[dict]) -> list[str]:
    lines = ["| section | cores | method | time (s) | CPU (s) | peak MB |",
             "|---|---:|---|---:|---:|---:|"]
    for row in rows:
        lines.append(f"| {row['section']} | {row['cores']} | {row['method']} | "
                     f"{row['seconds']:.2f} | {row['cpu_seconds']:.2f} | "
                     f"{row['peak_mb']:.0f} |")
    for row in rows:
        if "stages" in row:
            parts = ", ".join(f"{k} {v:.2f}" for k, v in row["stages"].items())
            lines.append(f"stages at {row['cores']} cores ({row['seconds']:.2f} s): {parts}")
        if row.get("cpu_stages"):
            parts = ", ".join(f"{k} {v:.2f}" for k, v in row["cpu_stages"].items())
            lines.append(f"CPU seconds at {row['cores']} cores ({row['cpu_seconds']:.2f} s): "
                         f"{parts}")
    return lines


def counts(text: str) -> list[int]:
    everything = all_cores()
    return [everything if v == "all" else min(int(v), everything) for v in text.split(",")]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.cores", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", default="4000x6000", help="HEIGHTxWIDTH of the merge (24 MP)")
    parser.add_argument("--cores", default="2,all", help="core counts of the merge rows")
    parser.add_argument("--scaling", default="1,2,4,8,all",
                        help="core counts of the stage-by-stage rows ('' for none)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--sets", type=int, default=48, help="the shoot's sets (0: no shoot)")
    parser.add_argument("--shoot-size", default="3000x4000")
    parser.add_argument("--workers", default="1,4,all")
    parser.add_argument("--dask", default="all")
    parser.add_argument("--baseline", type=Path, default=None, metavar="TREE",
                        help="a folder holding another commit's hdrio/ package, whose "
                             "merge runs alternated with this one's")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    height, width = (int(v) for v in args.size.split("x"))
    args.out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    print(f"{all_cores()} CPUs; merge {width}x{height}", flush=True)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="hdrio-cores-") as folder:
        folder = Path(folder)
        ladder, _ = bracket_stack(height, width, count=9)
        paths = [str(p) for p in write_jpegs(ladder, folder)]
        exposures = [repr(float(t)) for t in ladder.exposures]
        ladder = None
        env = {"NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR",
                                                 str(folder / "kernel-cache"))}
        first = timed([*hdrio_command(), "merge", *paths[1:8], "--exposures",
                       ",".join(exposures[1:8]), "-o", str(folder / "merge7.exr"), "-q"],
                      env)
        print(f"first merge (fills the kernel cache): {first['seconds']:.2f} s", flush=True)
        np.save(folder / "written.npy",
                read_image(folder / "merge7.exr")[0].astype(np.float16))
        if args.baseline is not None:  # its kernels compiled before the timed runs
            baseline = merge_rows(paths, exposures, folder, [all_cores()], 1, env,
                                  args.baseline)
            print(f"baseline: {args.baseline}, its merge once: "
                  f"{baseline[-1]['seconds']:.2f} s", flush=True)
        rows += merge_rows(paths, exposures, folder, counts(args.cores), args.repeats, env,
                           args.baseline)
        rows += peak_rows(paths, exposures, folder, env)
        if args.scaling:
            rows += scaling_rows(paths, exposures, folder, counts(args.scaling), env)
        for row in demo_rows(hdrio_command(), folder):
            rows.append({"section": "first run", "cores": all_cores(), "peak_mb":
                         row["process_peak_mb"], **row})
        print("\n".join(table(rows)), flush=True)
    found = ratios(rows)
    for name, ratio in found.items():
        print(f"{name}: {ratio:.2f}")
    document = {"cpus": all_cores(), "size": args.size, "rows": rows, "ratios": found,
                "when": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}
    (args.out / "cores.json").write_text(json.dumps(document, indent=2) + "\n")
    print(f"merge rows took {time.perf_counter() - started:.0f} s", flush=True)
    if args.sets:
        workers = ",".join(str(v) for v in counts(args.workers))
        dask = ",".join(str(v) for v in counts(args.dask)) if args.dask else "none"
        farm.main(["--sets", str(args.sets), "--size", args.shoot_size, "--workers", workers,
                   "--dask", dask, "--no-pinned", "--json", str(args.out / "farm.json"),
                   *(["--baseline", str(args.baseline)] if args.baseline else [])])
    print(f"wrote {args.out / 'cores.json'} ({time.perf_counter() - started:.0f} s in all)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
