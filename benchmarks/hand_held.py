"""The generator's hand-held ladders against the same stacks held still (issue 28's bounds:
median error at most 1.3x the still stack's, p99 at most 2x).

``python -m benchmarks.hand_held [--frames 7] [--seeds 0-19] [--true-warps]
[--encoding png|16-bit]``: for each
seed, :func:`tests.hard_cases.hand_held` merged with the defaults and the same stack held
still, the radiance error in the reference's frame over the well-exposed pixels (a 16 px
border left out), median and p99 over the still stack's; the worst corner error of the
registered brackets (px, against their true warps) and the brackets refused.
``--true-warps`` is an oracle: every measured warp is replaced by the true one (the
refusals stand), which shows what resampling alone costs. ``--lens SIGMA`` blurs every
view by a lens's point spread before capture (the generator's default has none: edges
sharper than any lens gives). Prints a table and writes
``benchmarks/results/hand_held.json``.

``python -m benchmarks.hand_held --registration [--seeds 0-3]``: registration alone
(deghosting off) on :func:`tests.hard_cases.hand_held_walkers`' JPEG ladders without the
figure (GoldenGate, StillLife, MtTamWest and Desk, 5 and 7 x 2 EV): per ladder and seed,
the worst corner error of the registered brackets and the brackets refused.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np


def seeds_of(text: str) -> list[int]:
    """``"0-19"`` or ``"0,3,7"`` as a list of seeds."""
    if "-" in text:
        first, last = (int(v) for v in text.split("-"))
        return list(range(first, last + 1))
    return [int(v) for v in text.split(",")]


def with_true_warps(case):
    """A context in which registration reports ``case``'s true warps (an oracle)."""
    import contextlib

    import hdrio.align.registration as registration
    from hdrio.align.lucaskanade import corner_motion

    measure = registration.estimate_alignment

    def truth(stack, response, model="euclidean", excluded=None):
        alignment = measure(stack, response, model, excluded)
        inverse = np.linalg.inv(case.warps[alignment.reference])
        transforms = np.stack([warp @ inverse for warp in case.warps])
        height, width = stack.codes.shape[1:3]
        return dataclasses.replace(alignment, transforms=transforms, motion=tuple(
            corner_motion(t, height, width) for t in transforms))

    @contextlib.contextmanager
    def patched():
        registration.estimate_alignment = truth
        try:
            yield
        finally:
            registration.estimate_alignment = measure

    return patched()


def measure(frames: int, seed: int, true_warps: bool, lens: float = 0.0,
            encoding: str = "png") -> dict:
    """One seed's row (``lens``, ``encoding``: :func:`tests.hard_cases.hand_held`'s)."""
    import contextlib

    from hdrio.job.options import MergeOptions
    from hdrio.job.run import merge_stack
    from hdrio.tools.synthetic import radiance_error, well_exposed
    from tests.hard_cases import hand_held

    moving = hand_held(frames, seed, lens=lens, encoding=encoding)
    held = hand_held(frames, seed, still=True, lens=lens, encoding=encoding)
    with with_true_warps(moving) if true_warps else contextlib.nullcontext():
        result = merge_stack(moving.stack(), MergeOptions())
    still = merge_stack(held.stack(), MergeOptions())
    alignment = result.motion.alignment
    height, width = moving.codes.shape[1:3]
    inner = np.zeros((height, width), bool)
    inner[16:-16, 16:-16] = True
    inner &= well_exposed(held.codes, held.camera.code_max)
    moved = radiance_error(result.radiance, moving.truth_in(alignment.reference), inner)
    base = radiance_error(still.radiance, held.truth_in(alignment.reference), inner)
    refused = sorted(j for j, _ in alignment.refused)
    errors = [e for j, e in enumerate(moving.corner_errors(alignment)) if j not in refused]
    return {"seed": seed, "median": moved["median"] / base["median"],
            "p99": moved["p99"] / base["p99"], "worst_px": max(errors), "refused": refused}


LADDERS = (("GoldenGate", 7), ("StillLife", 5), ("StillLife", 7), ("MtTamWest", 7),
           ("Desk", 7))
"""The walker ladders :func:`registration` measures (scene, brackets; 2 EV apart)."""


def registration(seeds: list[int], ladders=LADDERS) -> list[dict]:
    """Per ladder (``(scene, brackets)``, :data:`LADDERS`) and seed: the worst registered
    bracket's corner error (px) and the brackets refused."""
    from hdrio.job.options import MergeOptions
    from hdrio.job.run import merge_stack
    from tests.hard_cases import hand_held_walkers

    rows = []
    for scene, frames in ladders:
        for seed in seeds:
            case = hand_held_walkers(scene, frames, 2.0, seed, figure=False)
            alignment = merge_stack(case.stack(), MergeOptions(deghost="off")).motion.alignment
            refused = sorted(j for j, _ in alignment.refused)
            errors = [e for j, e in enumerate(case.corner_errors(alignment))
                      if j not in refused]
            rows.append({"scene": scene, "frames": frames, "seed": seed,
                         "worst_px": max(errors), "refused": refused})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=7)
    parser.add_argument("--seeds", default="0-19")
    parser.add_argument("--true-warps", action="store_true")
    parser.add_argument("--lens", type=float, default=0.0,
                        help="a Gaussian point spread (px) on every view, as a lens gives")
    parser.add_argument("--encoding", default="png", choices=("png", "16-bit"),
                        help="sRGB 8-bit codes or linear 16-bit ones")
    parser.add_argument("--registration", action="store_true")
    parser.add_argument("--json", default="benchmarks/results/hand_held.json")
    args = parser.parse_args(argv)
    if args.registration:
        rows = registration(seeds_of(args.seeds))
        print("walker ladders without the figure (JPEG, 2 EV): worst registered bracket "
              "(px), brackets refused")
        for row in rows:
            print(f"{row['scene']} {row['frames']} seed {row['seed']}: "
                  f"{row['worst_px']:.2f} {row['refused']}")
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"registration": rows}, indent=1))
        return 0
    rows = [measure(args.frames, seed, args.true_warps, args.lens, args.encoding)
            for seed in seeds_of(args.seeds)]
    print(f"hand_held({args.frames}{f', lens={args.lens:g}' if args.lens else ''}"
          f"{f', {args.encoding}' if args.encoding != 'png' else ''})"
          f"{' with the true warps' if args.true_warps else ''}: "
          "error over the still stack's (bounds: median 1.3x, p99 2x)")
    print("seed | median | p99 | worst registered bracket (px) | refused")
    for row in rows:
        print(f"{row['seed']} | {row['median']:.3f} | {row['p99']:.3f} | "
              f"{row['worst_px']:.2f} | {row['refused']}")
    within = sum(row["median"] <= 1.3 for row in rows), sum(row["p99"] <= 2.0 for row in rows)
    print(f"within the bounds: median {within[0]} of {len(rows)}, p99 {within[1]} of "
          f"{len(rows)}")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"frames": args.frames, "true_warps": args.true_warps,
                               "lens": args.lens, "encoding": args.encoding, "rows": rows},
                              indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
