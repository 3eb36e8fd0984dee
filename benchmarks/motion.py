"""Speed of alignment and deghosting at full size, against the merge in the same run.

``python -m benchmarks.motion [--size 4000x6000] [--brackets 7] [--repeats 2]``: the speed
benchmark's demo scene (``benchmarks.speed.scene``), 8-bit, 2 EV apart, with the true
response given (no solve, so only the steps measured run). Three runs of
:func:`hdrio.pipeline.merge_stack`, each timed by the pipeline's own phase timers (best of
``--repeats``), the merge of each as its baseline:

``static auto``
    a still stack with ``--align auto --deghost auto`` against the same stack with both
    ``off``: the extra time of the whole call (the quick check, and the deghosting test
    that finds nothing: no warp, no re-merge) over the merge's own. Target: <= 10 %.
    (The alignment's share alone is reported too.)
``moving``
    every bracket but the reference shifted (up to 8 px) and rotated (up to 0.5 deg),
    ``--align auto --deghost auto``. Targets: alignment <= 0.5 s per moved bracket,
    deghosting (test + re-merge) <= the merge.

Prints a table and writes ``benchmarks/results/motion.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from benchmarks.speed.scene import bracket_stack, true_response
from hdrio.align.registration import reference_bracket
from hdrio.align.warp import warp_codes
from hdrio.parallel import threads
from hdrio.pipeline import MergeOptions, merge_stack
from hdrio.stack import ExposureStack


def moved(stack: ExposureStack, seed: int = 0) -> ExposureStack:
    """``stack`` with every bracket but the best exposed warped by a random shift and
    rotation about the centre."""
    rng = np.random.default_rng(seed)
    height, width = stack.shape[:2]
    reference = reference_bracket(stack.codes, stack.code_max)
    codes = np.empty_like(stack.codes)
    cx, cy = (width - 1) / 2, (height - 1) / 2
    centre = np.array([[1.0, 0, cx], [0, 1.0, cy], [0, 0, 1.0]])
    for j in range(stack.count):
        if j == reference:
            codes[j] = stack.codes[j]
            continue
        a = np.radians(rng.uniform(-0.5, 0.5))
        dx, dy = rng.uniform(-8, 8, 2)
        motion = np.array([[np.cos(a), -np.sin(a), dx], [np.sin(a), np.cos(a), dy],
                           [0, 0, 1.0]])
        warp_codes(stack.codes[j], np.linalg.inv(centre @ motion @ np.linalg.inv(centre)),
                   stack.code_max, codes[j])
    return ExposureStack.from_arrays(codes, stack.exposures)


def best(stack: ExposureStack, options: MergeOptions, repeats: int, response) -> dict:
    runs, walls = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        runs.append(merge_stack(stack, options, response=response))
        walls.append(time.perf_counter() - start)
    timings = {key: min(r.timings.get(key, 0.0) for r in runs) for key in runs[0].timings}
    timings["total"] = min(walls)
    result = runs[-1]
    timings["moved"] = sum(1 for m in result.motion.alignment.motion if m > 0) \
        if result.motion.alignment else 0
    timings["warped"] = bool(result.motion.warped)
    timings["deghosted_fraction"] = (result.motion.deghosting.fraction
                                     if result.motion.deghosting else None)
    return timings


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="4000x6000", help="HEIGHTxWIDTH")
    parser.add_argument("--brackets", type=int, default=7)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--json", default="benchmarks/results/motion.json")
    args = parser.parse_args(argv)
    height, width = (int(v) for v in args.size.split("x"))
    stack, _ = bracket_stack(height, width, args.brackets)
    response = true_response()
    auto = MergeOptions(align="auto", deghost="auto")  # spelt out: whatever the defaults
    merge_stack(moved(bracket_stack(64 * 6, 64 * 8, 3)[0]), auto, response=response)  # jit
    off = MergeOptions(align="off", deghost="off")
    plain = best(stack, off, args.repeats, response)
    static = best(stack, auto, args.repeats, response)
    moving_stack = moved(stack)
    del stack
    moving = best(moving_stack, auto, args.repeats, response)
    rows = {
        # The whole call's extra time: the noise model that deghosting fits is the one
        # the (noise-aware) merge uses, so the phases alone would over-count it.
        "static auto: extra time / merge (off)":
            (static["total"] - plain["total"]) / plain["merge"],
        "static auto: align / merge": static["align"] / static["merge"],
        "moving: alignment per moved bracket (s)": moving["align"] / max(1, moving["moved"]),
        "moving: deghosting / merge": moving["deghost"] / moving["merge"],
    }
    targets = {"static auto: extra time / merge (off)": 0.10,
               "static auto: align / merge": 0.10,
               "moving: alignment per moved bracket (s)": 0.5,
               "moving: deghosting / merge": 1.0}
    print(f"{args.brackets} brackets of {height}x{width}, {threads()} threads, "
          f"load {os.getloadavg()[0]:.1f}")
    print(f"{'measure':44s} {'value':>8s} {'target':>8s}")
    for name, value in rows.items():
        print(f"{name:44s} {value:8.3f} {targets[name]:8.2f}")
    print(f"off: {plain}\nstatic: {static}\nmoving: {moving}")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"size": [height, width], "brackets": args.brackets,
                               "threads": threads(), "load": os.getloadavg()[0],
                               "rows": rows, "targets": targets, "off": plain, "static": static,
                               "moving": moving}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
