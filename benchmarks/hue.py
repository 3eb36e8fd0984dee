"""Hue on clip-transition pixels: the saturation policies on camera-like brackets.

    python -m benchmarks.hue [--width 300] [--out benchmarks/results]

Each ``openexr_scenes`` photograph is rendered as 7 brackets 2 EV apart through a camera
that clips its raw channels, white-balances them and mixes them with its colour matrix
after the clip (:func:`hdrio.synthetic.render_camera_brackets`, the 5D Mark II's matrix),
and through the same camera without the mixing (the control). Each stack is merged with
the true response and the default estimator under every saturation policy, and under
the *oracle*, which drops exactly the raw-clipped observations (what no policy can beat).
The hue angle error (:func:`hdrio.synthetic.hue_angle_error`, degrees) is measured on the
clip-transition pixels: some but not all raw channels clipped in some bracket, nothing
clipped in the shortest. With sensor noise and without (codes' rounding only: the
policy's bias alone, since the colour matrix also multiplies chroma noise about 2.5x).
Prints a table and writes ``hue.json``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.truth.scenes import REPO_ROOT, SCENES, builtin_scenes
from benchmarks.truth.stacks import exposure_ladder
from hdrio.merge.estimators import MERGE_METHODS
from hdrio.merge.saturation import SATURATION_POLICIES
from hdrio.stack import ExposureStack
from hdrio.synthetic import gamma_inverse_response, hue_angle_error, render_camera_brackets

VARIANTS = (*SATURATION_POLICIES, "oracle")


def measure(scene, quiet: bool) -> dict[str, dict[str, float]]:
    """p99 hue error (degrees) per camera (``mixed``, ``unmixed``) and variant."""
    noise = {"shot_noise": 0.0, "read_noise": 0.0} if quiet else {}
    times = exposure_ladder(scene, 7, 2.0)
    response, _ = gamma_inverse_response()
    out: dict[str, dict[str, float]] = {}
    mask = None
    for mixing in (True, False):
        codes, clipped = render_camera_brackets(scene.radiance, times, mixing=mixing, seed=1,
                                                **noise)
        if mask is None:  # the mixed camera's transition pixels, for both cameras
            n = clipped.sum(axis=-1)
            mask = (np.any((n > 0) & (n < 3), axis=0) & ~np.any(clipped[0], axis=-1)
                    & ~np.any(codes[0] == 255, axis=-1))
        row = {}
        for variant in VARIANTS:
            policy, data = variant, codes
            if variant == "oracle":
                policy, data = "channel", codes.copy()
                data[np.any(clipped, axis=-1)] = 255
            stack = ExposureStack.from_arrays(data, times,
                                              files=[f"f{j}.png" for j in range(len(times))])
            radiance, _ = MERGE_METHODS["inverse-variance"](stack, response,
                                                            saturation=policy)
            error = hue_angle_error(radiance, scene.radiance, mask)
            row[variant] = float(np.percentile(error, 99)) if error.size else float("nan")
        out["mixed" if mixing else "unmixed"] = row
    out["pixels"] = {"transition": int(np.count_nonzero(mask))}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.hue", description=__doc__)
    parser.add_argument("--width", type=int, default=300)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "benchmarks" / "results")
    args = parser.parse_args(argv)
    results = {}
    header = "| scene | noise | camera | " + " | ".join(VARIANTS) + " |"
    print(header)
    print("|" + "---|" * (3 + len(VARIANTS)))
    for scene in builtin_scenes(SCENES, args.width):
        for quiet in (False, True):
            label = "rounding only" if quiet else "shot + read"
            result = measure(scene, quiet)
            results[f"{scene.name}/{label}"] = result
            for camera in ("mixed", "unmixed"):
                cells = " | ".join(f"{result[camera][v]:.1f}" for v in VARIANTS)
                print(f"| {scene.name} | {label} | {camera} | {cells} |", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "hue.json"
    path.write_text(json.dumps({"width": args.width, "results": results}, indent=1))
    print(f"p99 hue angle error (degrees) on clip-transition pixels; wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
