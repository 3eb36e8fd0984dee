"""Still ladders of 5, 7 and 9 brackets: what ``--align auto --deghost auto`` costs over
both ``off``, and the process's peak memory, as the bracket count grows.

``python -m benchmarks.motion_ladder [--size 4000x6000] [--brackets 5,7,9]``: the speed
benchmark's demo scene (``benchmarks.speed.scene``), 8-bit, 2 EV apart, the true response
given. Each (count, mode) runs in a process of its own (its peak is the process's
``ru_maxrss``), the stack handed over as ``hdrio merge`` hands the brackets it read
(staged beyond ``HDRIO_MEMORY_BUDGET_MB``, ``owned``). The issue's bounds (28): the
auto call's wall time within 10 % of the off call's, the peak flat (within 10 %) from 5
to 9 brackets; and nothing warped or deghosted, the pixels identical. Prints a table and
writes ``benchmarks/results/motion_ladder.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path


def child(height: int, width: int, count: int, mode: str, out: str) -> None:
    """One merge in this process; writes its timings, peak and result to ``out``."""
    import numpy as np

    from benchmarks.motion import fresh_copy
    from benchmarks.speed.scene import bracket_stack, true_response
    from hdrio.job.options import MergeOptions
    from hdrio.job.run import merge_stack

    stack, _ = bracket_stack(height, width, count)
    response = true_response()
    options = MergeOptions(align=mode, deghost=mode)
    merge_stack(bracket_stack(96, 128, count)[0], options, response=response)  # compile
    fresh = fresh_copy(stack)
    del stack
    start, cpu = time.perf_counter(), time.process_time()
    result = merge_stack(fresh, options, response=response, owned=True)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    motion = result.motion
    checksum = float(np.sum(result.radiance, dtype=np.float64))
    Path(out).write_text(json.dumps({
        "wall": wall, "cpu": cpu, "peak_mb": resource.getrusage(
            resource.RUSAGE_SELF).ru_maxrss / 1024, "checksum": checksum,
        "warped": bool(motion.warped),
        "deghosted": None if motion.deghosting is None else motion.deghosting.fraction,
        "align": result.timings.get("align", 0.0),
        "deghost": result.timings.get("deghost", 0.0)}))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="4000x6000", help="HEIGHTxWIDTH")
    parser.add_argument("--brackets", default="5,7,9")
    parser.add_argument("--json", default="benchmarks/results/motion_ladder.json")
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    height, width = (int(v) for v in args.size.split("x"))
    if args.child:
        count, mode, out = int(args.child[0]), args.child[1], args.child[2]
        child(height, width, count, mode, out)
        return 0
    rows = []
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    load = [os.getloadavg()[0]]
    for count in (int(v) for v in args.brackets.split(",")):
        row = {"brackets": count}
        for mode in ("off", "auto"):
            scratch = out.with_suffix(f".{count}.{mode}.tmp")
            subprocess.run([sys.executable, "-m", "benchmarks.motion_ladder", "--size",
                            args.size, "--child", str(count), mode, str(scratch)],
                           check=True)
            row[mode] = json.loads(scratch.read_text())
            scratch.unlink()
        row["extra_wall"] = row["auto"]["wall"] / row["off"]["wall"] - 1.0
        row["identical"] = row["auto"]["checksum"] == row["off"]["checksum"]
        rows.append(row)
    load.append(os.getloadavg()[0])
    peaks = [row["auto"]["peak_mb"] for row in rows]
    print(f"still ladders of {args.size}, load average {load[0]:.1f} before, "
          f"{load[1]:.1f} after")
    print(f"{'brackets':>8s} {'off s':>7s} {'auto s':>7s} {'extra':>7s} {'peak off':>9s} "
          f"{'peak auto':>9s} {'warped':>6s} {'deghosted':>9s} {'identical':>9s}")
    for row in rows:
        print(f"{row['brackets']:8d} {row['off']['wall']:7.2f} {row['auto']['wall']:7.2f} "
              f"{100 * row['extra_wall']:6.1f}% {row['off']['peak_mb']:8.0f}M "
              f"{row['auto']['peak_mb']:8.0f}M {row['auto']['warped']!s:>6s} "
              f"{100 * (row['auto']['deghosted'] or 0):8.3f}% {row['identical']!s:>9s}")
    print(f"peak (auto) from {rows[0]['brackets']} to {rows[-1]['brackets']} brackets: "
          f"{100 * (max(peaks) / min(peaks) - 1):.1f} % apart (bound 10 %)")
    out.write_text(json.dumps({"size": [height, width], "load": load, "rows": rows},
                              indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
