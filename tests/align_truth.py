"""Ground truth for alignment and deghosting: a real EXR scene seen by a moving camera.

The scene is cropped at twice the stack's resolution, each bracket's view warped there
(a cubic spline on radiance, then a 2x2 area average: what a sensor pixel integrates), and
rendered through a measured camera response (DoRF) with the truth harness's noise.
The reference bracket sees the scene unwarped, so the still stack's truth is the crop.

``python -m tests.align_truth [seeds]`` prints, for the GoldenGate stack of
``tests/test_align.py``, each seed's merged error against the same stack held still
(median and p99 ratios, the default merge and the log merge): the table in
docs/motion.md.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

from benchmarks.truth.curves import load_curve
from benchmarks.truth.scenes import data_folder, read_scene
from benchmarks.truth.stacks import READ_NOISE, SHOT_NOISE
from hdrio.align.lucaskanade import rescale
from hdrio.tools.synthetic import render_brackets

SUPER = 2


def euclidean(dx: float, dy: float, degrees: float, height: int, width: int) -> np.ndarray:
    """``x_moving = W x_reference``: a rotation by ``degrees`` about the image centre, then
    a shift of ``dx, dy`` pixels."""
    a = np.radians(degrees)
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    centre = np.array([[1.0, 0, cx], [0, 1.0, cy], [0, 0, 1.0]])
    rotation = np.array([[np.cos(a), -np.sin(a), dx], [np.sin(a), np.cos(a), dy], [0, 0, 1.0]])
    return centre @ rotation @ np.linalg.inv(centre)


def scene_crop(name: str, height: int, width: int, top: int = 0, left: int = 0) -> np.ndarray:
    """``(2 height, 2 width, 3)`` radiance from the full-resolution EXR (clamped >= 0)."""
    scene = read_scene(data_folder("openexr_scenes") / f"{name}.exr").radiance
    return np.ascontiguousarray(scene[top:top + SUPER * height, left:left + SUPER * width])


def view(crop: np.ndarray, warp: np.ndarray, objects=()) -> np.ndarray:
    """The radiance a bracket records, ``(H, W, 3)``: ``crop`` seen through ``warp`` (stack
    pixels), with ``objects`` (``(top, left, h, w, rgb)`` in stack pixels, drawn in the
    moving bracket's own frame) pasted over it."""
    hi = crop
    if not np.allclose(warp, np.eye(3)):
        inverse = np.linalg.inv(rescale(warp, SUPER))
        y, x = np.mgrid[0:hi.shape[0], 0:hi.shape[1]].astype(np.float64)
        w = inverse[2, 0] * x + inverse[2, 1] * y + inverse[2, 2]
        sx = (inverse[0, 0] * x + inverse[0, 1] * y + inverse[0, 2]) / w
        sy = (inverse[1, 0] * x + inverse[1, 1] * y + inverse[1, 2]) / w
        hi = np.stack([scipy.ndimage.map_coordinates(crop[..., c], [sy, sx], order=3,
                                                     mode="nearest") for c in range(3)], -1)
        hi = np.maximum(hi, 0.0)  # the spline's ringing below dark edges
    h, w = hi.shape[0] // SUPER, hi.shape[1] // SUPER
    out = hi.reshape(h, SUPER, w, SUPER, 3).mean(axis=(1, 3))
    for top, left, oh, ow, rgb in objects:
        out[top:top + oh, left:left + ow] = rgb
    return out.astype(np.float32)


def render(views: list[np.ndarray], exposures, curve: str = "dorf50", seed: int = 0
           ) -> np.ndarray:
    """Codes ``(P, H, W, 3)`` uint8 of each view at its exposure through a DoRF curve."""
    response = load_curve(curve).response
    return np.stack([render_brackets(v, [t], response, shot_noise=SHOT_NOISE,
                                     read_noise=READ_NOISE, seed=seed + j)[0]
                     for j, (v, t) in enumerate(zip(views, exposures))])


def ladder(truth: np.ndarray, frames: int = 3, ev: float = 2.0) -> np.ndarray:
    """Exposure times ``ev`` stops apart with the middle one putting the log-average at
    0.18 (the truth harness's ladder)."""
    key = float(np.exp(np.mean(np.log(1e-4 + truth.mean(axis=-1)))))
    return 0.18 / key * 2.0 ** (ev * (np.arange(frames) - (frames - 1) / 2.0))


def moving_views(crop: np.ndarray, reference: int, count: int, height: int, width: int,
                 seed: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The warps (shifts up to +-8 px, rotations up to +-0.5 deg, the reference's the
    identity) and views of a hand-held stack of ``count`` brackets."""
    rng = np.random.default_rng(seed)
    warps = [euclidean(*rng.uniform(-8, 8, 2), rng.uniform(-0.5, 0.5), height, width)
             for _ in range(count)]
    warps[reference] = np.eye(3)
    return warps, [view(crop, w) for w in warps]


def main(seeds: list[int]) -> None:
    from hdrio.align.registration import reference_bracket
    from hdrio.job.run import MergeOptions, merge_stack
    from hdrio.stack import ExposureStack
    from hdrio.tools.synthetic import radiance_error, well_exposed

    height, width, margin = 300, 400, 24  # tests/test_align.py's
    crop = scene_crop("GoldenGate", height, width, 100, 30)
    truth = view(crop, np.eye(3))
    exposures = ladder(truth, 3)
    still = ExposureStack.from_arrays(render([truth] * 3, exposures), exposures)
    inner = np.zeros((height, width), bool)
    inner[margin:-margin, margin:-margin] = True
    inner &= well_exposed(still.codes, still.code_max)
    reference = reference_bracket(still.codes, still.code_max)
    print("seed | default median / still | default p99 / still | log median / still "
          "| log p99 / still")
    for seed in seeds:
        _, views = moving_views(crop, reference, 3, height, width, seed)
        moving = ExposureStack.from_arrays(render(views, exposures, seed=seed), exposures)
        ratios = []
        for merge in ("inverse-variance", "log"):
            base = radiance_error(merge_stack(still, MergeOptions(merge=merge)).radiance,
                                  truth, inner)
            aligned = radiance_error(merge_stack(moving, MergeOptions(merge=merge)).radiance,
                                     truth, inner)
            ratios += [aligned["median"] / base["median"], aligned["p99"] / base["p99"]]
        print(f"{seed} | " + " | ".join(f"{r:.2f}" for r in ratios))


if __name__ == "__main__":
    import sys

    main([int(a) for a in sys.argv[1:]] or [0, 1, 2, 3])
