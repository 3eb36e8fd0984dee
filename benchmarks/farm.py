"""A shoot on several workers: throughput of ``--group`` with N workers against 1.

12 bracket sets of 7 JPEGs at 12 MP (the demo scene, tiled; each set's files are hard
links to one rendered ladder, named by the file-name convention), merged to half EXRs by
the ``hdrio`` command as a user runs it, one fresh process per row:

* ``--threads 1``: one worker, the sets one after another in the process (the baseline);
* the same pinned to one core (its affinity set as ``taskset -c 0`` sets it): one farm
  slot, the unit a farm manager hands out; a worker's merge is itself multi-threaded, so
  one unpinned worker already keeps most of two cores busy and a second worker can add
  only what it leaves idle, while workers of one core each show how the engine scales
  with workers (``--no-pinned`` leaves it out);
* ``--threads N``: a local pool of N worker processes, for each N of ``--workers``
  (default ``1,2``; the 16-core device's run, :mod:`benchmarks.cores`: ``--sets 48
  --workers 1,4,16 --dask 16``);
* ``--dask local:N``: a Dask ``LocalCluster`` of as many (each N of ``--dask``; by
  default every N of ``--workers``);
* ``hdrio merge`` of one set: the single-run memory budget;
* with ``--baseline TREE`` (a folder holding another commit's ``hdrio/``), every row but
  the single set again right after it, by that tree's ``hdrio`` (started in the
  temporary folder, writing to folders of its own), and each row's throughput against
  the baseline's: a change to how sets run, measured against its parent in one run.

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
import sys
import tempfile
import time
from fractions import Fraction
from pathlib import Path

from benchmarks.speed.endtoend import write_jpegs
from benchmarks.speed.process import baseline_environment, timed
from benchmarks.speed.scene import bracket_stack

DEFAULT_OUT = Path(__file__).parent / "results"
_PEAK = re.compile(r"worker peak (\d+) MB")


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


def measure(command: list[str], cores: int = 0, env: dict[str, str] | None = None,
            cwd: Path | None = None) -> dict:
    """Run ``command`` in a fresh process (on the first ``cores`` CPUs when given; with
    ``env`` added, in ``cwd``); wall seconds, CPU seconds, the largest process's peak
    (MB), per-set worker peaks, the load average before and after."""
    load_before = os.getloadavg()[0]
    result = timed(command, env, cores=cores, cwd=cwd)
    peaks = [int(p) for p in _PEAK.findall(result["output"])]
    return {"seconds": result["seconds"], "process_peak_mb": result["peak_mb"],
            "cpu_seconds": result["cpu_seconds"],
            "worker_peak_mb": max(peaks) if peaks else None,
            "load_before": load_before, "load_after": os.getloadavg()[0]}


BASELINE = " (baseline)"
"""Appended to a row's name when the ``--baseline`` tree's ``hdrio`` ran it."""


def _elsewhere(command: list[str], folder: Path) -> list[str]:
    """``command`` writing its output (``-o``, a path under ``folder``) under
    ``folder/baseline`` instead (the same folders would be found done, recorded in the
    journal)."""
    at = command.index("-o") + 1
    output = folder / "baseline" / Path(command[at]).relative_to(folder)
    return [*command[:at], str(output), *command[at + 1:]]


def _row(name: str, sets: int, measured: dict) -> dict:
    """A row of the table, printed as it is made."""
    row = {"run": name, "sets": sets, **measured}
    row["sets_per_minute"] = 60 * sets / row["seconds"]
    row["cpu_seconds_per_set"] = row["cpu_seconds"] / sets
    print(f"{name:48s} {row['seconds']:7.1f} s  {row['sets_per_minute']:6.2f} sets/min"
          f"  CPU {row['cpu_seconds']:6.1f} s ({row['cpu_seconds'] / row['seconds']:.2f}"
          f" cores, {row['cpu_seconds_per_set']:.2f} s a set)"
          f"  process peak {row['process_peak_mb']:6.0f} MB  worker peak "
          f"{row['worker_peak_mb'] or float('nan'):6.0f} MB  load "
          f"{row['load_before']:.1f} -> {row['load_after']:.1f}", flush=True)
    return row


def runs(hdrio: list[str], folder: Path, shoot: Path, sets: int, workers: list[int],
         dask: list[int], pinned: bool = True) -> list[tuple[str, int, int, list[str]]]:
    """The rows, each ``(name, sets, cores, command)`` (``cores`` 0: every CPU): one set
    alone, one worker pinned to one core (when ``pinned``), then for each count of
    ``workers`` the local pool (``--threads N``) and, for the counts also in ``dask``, a
    Dask ``LocalCluster`` (``--dask local:N``)."""
    one_set = sorted(shoot.glob("pos_a_*.jpg"))
    rows = [("hdrio merge, one set (single-run budget)", 1, 0,
             [*hdrio, "merge", *map(str, one_set), "-o", str(folder / "one.exr")])]
    if pinned:
        rows.append(("--group, 1 worker pinned to one core (affinity, as taskset -c 0)",
                     sets, 1, [*hdrio, "--threads", "1", str(shoot), "--group", "--merge",
                               "-o", f"{folder}/pinned/{{first_stem}}.exr"]))
    for count in workers:
        rows.append((f"--group, local pool of {count} (--threads {count})", sets, 0,
                     [*hdrio, "--threads", str(count), str(shoot), "--group", "--merge",
                      "-o", f"{folder}/pool{count}/{{first_stem}}.exr"]))
        if count in dask:
            rows.append((f"--group --dask local:{count}", sets, 0,
                         [*hdrio, str(shoot), "--dask", f"local:{count}", "--group",
                          "--merge", "-o", f"{folder}/dask{count}/{{first_stem}}.exr"]))
    return rows


def ratios(by_name: dict[str, dict], workers: list[int]) -> dict[str, float]:
    """Throughput of N workers against one (the pool's and Dask's), and Dask's against
    the pool's at the same N (sets per minute)."""
    def rate(name: str) -> float:
        return by_name[name]["sets_per_minute"]

    one = rate(f"--group, local pool of {workers[0]} (--threads {workers[0]})")
    result = {}
    for count in workers[1:]:
        pool = rate(f"--group, local pool of {count} (--threads {count})")
        result[f"pool {count} / {workers[0]} workers"] = pool / one
        if f"--group --dask local:{count}" in by_name:
            dask = rate(f"--group --dask local:{count}")
            result[f"dask local:{count} / pool {count}"] = dask / pool
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.farm", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sets", type=int, default=12)
    parser.add_argument("--frames", type=int, default=7)
    parser.add_argument("--size", default="3000x4000", help="HEIGHTxWIDTH (12 MP)")
    parser.add_argument("--workers", default="1,2",
                        help="worker counts, the first the baseline (the device's 16-core "
                             "run: 1,4,16)")
    parser.add_argument("--dask", default=None,
                        help="worker counts also run on a Dask LocalCluster (default: every "
                             "count of --workers; 'none' for none)")
    parser.add_argument("--no-pinned", dest="pinned", action="store_false",
                        help="leave out the row of one worker pinned to one core")
    parser.add_argument("--json", type=Path, default=DEFAULT_OUT / "farm.json")
    parser.add_argument("--baseline", type=Path, default=None, metavar="TREE",
                        help="a folder holding another commit's hdrio/ package: each "
                             "row but the single set runs again right after with it")
    args = parser.parse_args(argv)
    height, width = (int(v) for v in args.size.split("x"))
    workers = [int(v) for v in args.workers.split(",")]
    dask = (workers if args.dask is None else
            [] if args.dask == "none" else [int(v) for v in args.dask.split(",")])
    hdrio = [sys.executable, "-m", "hdrio"]
    rows = []
    with tempfile.TemporaryDirectory(prefix="hdrio-farm-") as folder:
        folder = Path(folder)
        shoot = make_shoot(folder, args.sets, args.frames, height, width)
        baseline = (None if args.baseline is None
                    else baseline_environment(args.baseline, folder))
        planned = runs(hdrio, folder, shoot, args.sets, workers, dask, args.pinned)
        if baseline is not None:  # its kernels into its cache before the timed rows
            timed(_elsewhere(planned[0][3], folder), baseline, cwd=folder)
        for name, sets, cores, command in planned:
            rows.append(_row(name, sets, measure(command, cores)))
            if baseline is not None and sets > 1:  # alternated, in the same minutes
                rows.append(_row(f"{name}{BASELINE}", sets,
                                 measure(_elsewhere(command, folder), cores, baseline, folder)))
    by_name = {row["run"]: row for row in rows}
    found = ratios(by_name, workers)
    for name in (name for name in by_name if f"{name}{BASELINE}" in by_name):
        found[f"{name}: this / the baseline (sets/min)"] = (
            by_name[name]["sets_per_minute"]
            / by_name[f"{name}{BASELINE}"]["sets_per_minute"])
    for name, ratio in found.items():
        print(f"throughput {name}: {ratio:.2f}x")
    document = {"cpus": os.cpu_count(), "sets": args.sets, "frames": args.frames,
                "size": args.size, "workers": workers, "rows": rows,
                "throughput_ratios": found,
                "when": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(document, indent=2) + "\n")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
