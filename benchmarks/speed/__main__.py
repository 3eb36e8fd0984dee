"""``python -m benchmarks.speed``: hdrio's speed and memory against its peers and the floor.

Prints a table and writes ``benchmarks/results/speed.json`` (see docs/speed.md).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from benchmarks.speed import endtoend, jit, merge, process, response, skips
from benchmarks.speed.scene import bracket_stack
from benchmarks.truth.harness import environment
from benchmarks.truth.scenes import REPO_ROOT

SECTIONS = ("process", "jit", "merge", "response", "endtoend", "skips")


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.speed", description=__doc__)
    parser.add_argument("--width", type=int, default=6000)
    parser.add_argument("--height", type=int, default=4000)
    parser.add_argument("--brackets", type=int, default=7, help="bracket count, 2 EV apart")
    parser.add_argument("--repeats", type=int, default=3, help="timed calls per row (median)")
    parser.add_argument("--only", default=",".join(SECTIONS),
                        help=f"comma-separated sections: {', '.join(SECTIONS)}")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "benchmarks" / "results")
    return parser.parse_args(argv)


def _ratio(rows: list[dict], numerator: str, denominator: str) -> float | None:
    times = {row["method"]: row.get("seconds") for row in rows}
    if times.get(numerator) and times.get(denominator):
        return times[numerator] / times[denominator]
    return None


def ratios(rows: list[dict]) -> dict[str, float | None]:
    """The acceptance ratios of issues #4 and #13, each from rows timed in this run."""
    return {
        "merge: OpenCV MergeDebevec / hdrio (log)":
            _ratio(rows, "OpenCV MergeDebevec", "hdrio merge (log)"),
        "merge: OpenCV MergeDebevec / hdrio (inverse-variance, the default)":
            _ratio(rows, "OpenCV MergeDebevec", "hdrio merge (inverse-variance)"),
        "merge: hdrio (inverse-variance, noise fit included) / hdrio (log)":
            _ratio(rows, "hdrio merge (inverse-variance)", "hdrio merge (log)"),
        "merge: hdrio (log, pixel rule: rows remapped) / hdrio (log, per channel)":
            _ratio(rows, "hdrio merge (log, pixel rule)", "hdrio merge (log)"),
        "merge: hdrio (inverse-variance, auto saturation) / (channel saturation)":
            _ratio(rows, "hdrio merge (inverse-variance)",
                   "hdrio merge (inverse-variance, channel saturation)"),
        "merge: hdrio (inverse-variance, highlights reconstruct) / (inverse-variance)":
            _ratio(rows, "hdrio merge (inverse-variance, highlights reconstruct)",
                   "hdrio merge (inverse-variance)"),
        "merge: hdrio (log) / floor": _ratio(rows, "hdrio merge (log)",
                                             "floor (copy of the codes, all cores)"),
        "merge: hdrio (linear) / floor": _ratio(rows, "hdrio merge (linear)",
                                                "floor (copy of the codes, all cores)"),
        "response: OpenCV / hdrio": _ratio(rows, "OpenCV CalibrateDebevec (defaults)",
                                           "hdrio response_Debevec1997 (defaults)"),
        "end to end: hdrio / I/O floor": _ratio(rows, next(
            (row["method"] for row in rows if row.get("end_to_end") == "hdrio"), ""),
            "I/O floor (decode JPEGs + write EXR)"),
        "end to end: hdrio / I/O floor decoding two at once": _ratio(rows, next(
            (row["method"] for row in rows if row.get("end_to_end") == "hdrio"), ""),
            "I/O floor, two JPEGs decoded at once as hdrio does"),
        **skips.saved_ratios(rows),
        **process.ratios(rows),
    }


def table(rows: list[dict]) -> list[str]:
    lines = ["| section | method | time (s) | CPU (s) | peak MB | error |",
             "|---|---|---:|---:|---:|---|"]
    for row in rows:
        error = ", ".join(f"{key} {row[key]:.4g}" for key in
                          ("median_error", "p99_error", "response_rms_stops") if key in row)
        seconds = f"{row['seconds']:.3f}" if "seconds" in row else row.get("skipped", "")
        peak = row.get("process_peak_mb", row.get("peak_mb"))
        peak = f"{peak:.0f}" if peak is not None else ""
        cpu = f"{row['cpu_seconds']:.2f}" if "cpu_seconds" in row else ""
        lines.append(f"| {row['row']} | {row['method']} | {seconds} | {cpu} | {peak} | "
                     f"{error} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    sections = [s.strip() for s in args.only.split(",") if s.strip()]
    unknown = sorted(set(sections) - set(SECTIONS))
    if unknown:
        print(f"unknown section(s): {', '.join(unknown)}", file=sys.stderr)
        return 2
    rows: list[dict] = []
    load_before = os.getloadavg()[0]
    if "process" in sections:  # first: the commands as users type them
        rows += process.run(args.height, args.width, args.repeats)
    if "jit" in sections:
        rows += jit.run()
    if {"merge", "response", "endtoend"} & set(sections):
        start = time.perf_counter()
        stack, radiance = bracket_stack(args.height, args.width, args.brackets)
        print(f"rendered {args.brackets} brackets {args.width}x{args.height} "
              f"in {time.perf_counter() - start:.1f} s", file=sys.stderr)
        if "merge" in sections:
            rows += merge.run(stack, radiance, args.repeats)
        if "response" in sections:
            rows += response.run(stack, args.repeats)
        if "endtoend" in sections:
            rows += endtoend.run(stack, args.repeats)
        stack = radiance = None
    if "skips" in sections:
        rows += skips.run(args.height, args.width, args.repeats)
    results = {"command": "python -m benchmarks.speed " + " ".join(argv or sys.argv[1:]),
               "size": [args.width, args.height], "brackets": args.brackets,
               "repeats": args.repeats, "load_average": [load_before, os.getloadavg()[0]],
               "environment": environment(), "rows": rows, "ratios": ratios(rows)}
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "speed.json"
    path.write_text(json.dumps(results, indent=2))
    report = markdown(results)
    (args.out / "speed.md").write_text(report)
    print(report)
    print(f"wrote {path} and {args.out / 'speed.md'}")
    return 0


def markdown(results: dict) -> str:
    """The run as markdown: command, machine, the table and the acceptance ratios."""
    environment = results["environment"]
    lines = [f"Command: `{results['command']}`; {results['brackets']} brackets of "
             f"{results['size'][0]}x{results['size'][1]}, median of {results['repeats']} "
             f"repeat(s); load average {results['load_average'][0]:.2f} -> "
             f"{results['load_average'][1]:.2f} on {environment.get('cpu_count', '?')} CPU(s); "
             f"commit {str(environment.get('git_commit', '?'))[:10]}.", "",
             *table(results["rows"]), "", "| ratio | value |", "|---|---:|"]
    lines += [f"| {name} | {value:.2f} |" for name, value in results["ratios"].items()
              if value is not None]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
