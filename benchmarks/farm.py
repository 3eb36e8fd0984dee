"""A shoot on several workers: throughput of ``--group`` with 2 workers against 1.

12 bracket sets of 7 JPEGs at 12 MP (the demo scene, tiled; each set's files are hard
links to one rendered ladder, named by the file-name convention), merged to half EXRs by
the ``hdrio`` command as a user runs it, one fresh process per row:

* ``--threads 1``: one worker, the sets one after another in the process (the baseline);
* the same pinned to one core (``taskset -c 0``): one farm slot, the unit a farm
  manager hands out; a worker's merge is itself multi-threaded, so one unpinned worker
  already keeps most of two cores busy and a second worker can add only what it leaves
  idle, while workers of one core each show how the engine scales with workers;
* ``--threads 2``: a local pool of two worker processes;
* ``--dask local:1`` and ``--dask local:2``: a Dask ``LocalCluster`` of one and two;
* ``hdrio merge`` of one set: the single-run memory budget.

Throughput is sets per minute of the whole command (start-up included), with the CPU
time of the command's processes (user + system) and the cores that makes on average; a
second worker can only help as far as one worker leaves a core idle. Peak memory is
each worker's own ``VmHWM`` as the command reports it per set, and the command's largest
process (``ru_maxrss`` of the children). The machine's load average is recorded before
and after each row: on a shared machine the ratios are what to read.

``python -m benchmarks.farm`` prints a table and writes ``benchmarks/results/farm.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from fractions import Fraction
from pathlib import Path

from benchmarks.speed.endtoend import write_jpegs
from benchmarks.speed.scene import bracket_stack

DEFAULT_OUT = Path(__file__).parent / "results"
_PEAK = re.compile(r"worker peak (\d+) MB")
_MEASURE = """
import resource, subprocess, sys, time
start = time.perf_counter()
code = subprocess.run(sys.argv[1:], capture_output=True, text=True)
seconds = time.perf_counter() - start
print(code.stdout + code.stderr)
usage = resource.getrusage(resource.RUSAGE_CHILDREN)
print("EXIT", code.returncode, "SECONDS", seconds, "PEAK_KB", usage.ru_maxrss,
      "CPU_S", usage.ru_utime + usage.ru_stime)
"""


def make_shoot(folder: Path, sets: int, frames: int, height: int, width: int) -> Path:
    """``sets`` sets of ``frames`` JPEGs: ``pos_a_1_3840.jpg`` ... (hard links)."""
    stack, _ = bracket_stack(height, width, count=frames)
    base = folder / "ladder"
    base.mkdir()
    paths = write_jpegs(stack, base)
    shoot = folder / "shoot"
    shoot.mkdir()
    letters = "abcdefghijklmnopqrstuvwxyz"
    for k in range(sets):
        for path, t in zip(paths, stack.exposures):
            ratio = Fraction(float(t)).limit_denominator(100_000)
            os.link(path, shoot / f"pos_{letters[k % 26] * (1 + k // 26)}_"
                                  f"{ratio.numerator}_{ratio.denominator}.jpg")
    return shoot


def measure(command: list[str]) -> dict:
    """Run ``command`` in a fresh process; wall seconds, exit code, largest process's
    peak (MB), per-set worker peaks, the load average before and after."""
    load_before = os.getloadavg()[0]
    completed = subprocess.run([sys.executable, "-c", _MEASURE, *command],
                               capture_output=True, text=True, check=True)
    last = completed.stdout.strip().splitlines()[-1].split()
    output = completed.stdout
    if last[1] != "0":
        raise RuntimeError(f"{' '.join(command)} failed:\n{output}")
    peaks = [int(p) for p in _PEAK.findall(output)]
    return {"seconds": float(last[3]), "process_peak_mb": int(last[5]) / 1024,
            "cpu_seconds": float(last[7]),
            "worker_peak_mb": max(peaks) if peaks else None,
            "load_before": load_before, "load_after": os.getloadavg()[0]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.farm", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sets", type=int, default=12)
    parser.add_argument("--frames", type=int, default=7)
    parser.add_argument("--size", default="3000x4000", help="HEIGHTxWIDTH (12 MP)")
    parser.add_argument("--json", type=Path, default=DEFAULT_OUT / "farm.json")
    args = parser.parse_args(argv)
    height, width = (int(v) for v in args.size.split("x"))
    hdrio = [sys.executable, "-m", "hdrio"]
    rows = []
    with tempfile.TemporaryDirectory(prefix="hdrio-farm-") as folder:
        folder = Path(folder)
        shoot = make_shoot(folder, args.sets, args.frames, height, width)
        one_set = sorted(shoot.glob("pos_a_*.jpg"))
        runs = [("hdrio merge, one set (single-run budget)", 1,
                 [*hdrio, "merge", *map(str, one_set), "-o", str(folder / "one.exr")]),
                ("--group, 1 worker (--threads 1)", args.sets,
                 [*hdrio, "--threads", "1", str(shoot), "--group", "--merge",
                  "-o", f"{folder}/pool1/{{first_stem}}.exr"]),
                ("--group, 1 worker pinned to one core (taskset -c 0)", args.sets,
                 ["taskset", "-c", "0", *hdrio, "--threads", "1", str(shoot), "--group",
                  "--merge", "-o", f"{folder}/pinned/{{first_stem}}.exr"]),
                ("--group, local pool of 2 (--threads 2)", args.sets,
                 [*hdrio, "--threads", "2", str(shoot), "--group", "--merge",
                  "-o", f"{folder}/pool2/{{first_stem}}.exr"]),
                ("--group --dask local:1", args.sets,
                 [*hdrio, str(shoot), "--dask", "local:1", "--group", "--merge",
                  "-o", f"{folder}/dask1/{{first_stem}}.exr"]),
                ("--group --dask local:2", args.sets,
                 [*hdrio, str(shoot), "--dask", "local:2", "--group", "--merge",
                  "-o", f"{folder}/dask2/{{first_stem}}.exr"])]
        for name, sets, command in runs:
            row = {"run": name, "sets": sets, **measure(command)}
            row["sets_per_minute"] = 60 * sets / row["seconds"]
            rows.append(row)
            print(f"{name:42s} {row['seconds']:7.1f} s  {row['sets_per_minute']:5.2f} sets/min"
                  f"  CPU {row['cpu_seconds']:6.1f} s ({row['cpu_seconds'] / row['seconds']:.2f}"
                  " cores)"
                  f"  process peak {row['process_peak_mb']:6.0f} MB  worker peak "
                  f"{row['worker_peak_mb'] or float('nan'):6.0f} MB  load "
                  f"{row['load_before']:.1f} -> {row['load_after']:.1f}", flush=True)
    by_name = {row["run"]: row for row in rows}
    ratios = {
        "pool 2 / 1 workers": by_name["--group, 1 worker (--threads 1)"]["seconds"]
        / by_name["--group, local pool of 2 (--threads 2)"]["seconds"],
        "dask 2 / 1 workers": by_name["--group --dask local:1"]["seconds"]
        / by_name["--group --dask local:2"]["seconds"],
        "pool 2 workers / 1 worker on one core": by_name[
            "--group, 1 worker pinned to one core (taskset -c 0)"]["seconds"]
        / by_name["--group, local pool of 2 (--threads 2)"]["seconds"],
        "dask 2 workers / 1 worker on one core": by_name[
            "--group, 1 worker pinned to one core (taskset -c 0)"]["seconds"]
        / by_name["--group --dask local:2"]["seconds"]}
    for name, ratio in ratios.items():
        print(f"throughput {name}: {ratio:.2f}x (target >= 1.6x)")
    document = {"cpus": os.cpu_count(), "sets": args.sets, "frames": args.frames,
                "size": args.size, "rows": rows, "throughput_ratios": ratios,
                "when": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(document, indent=2) + "\n")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
