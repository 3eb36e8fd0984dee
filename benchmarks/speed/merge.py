"""Merge of decoded brackets: hdrio's fused kernel against OpenCV's MergeDebevec and the floor.

All three get the same code values and the same (true) response, so the error column
compares the merges alone.
"""

from __future__ import annotations

import numpy as np

from benchmarks.speed.floor import parallel_copy
from benchmarks.speed.scene import true_response
from benchmarks.timing import measure_alternately, measure_call
from hdrio.merge.highlights import reconstruct_highlights
from hdrio.merge.methods import MERGE_METHODS
from hdrio.merge.weighted_mean import merge_brackets
from hdrio.radiometry.tables import estimate_tables
from hdrio.stack import ExposureStack
from hdrio.tools.synthetic import radiance_error, well_exposed


def reconstructed(stack: ExposureStack, response) -> np.ndarray:
    """The default merge, then ``--highlights reconstruct`` (as ``merge_stack`` calls it)."""
    radiance, statistics = MERGE_METHODS["inverse-variance"](stack, response)
    reconstruct_highlights(radiance, stack.codes[0], statistics.limits,
                           estimate_tables(response, stack.channel_exposures, "linear")[0],
                           statistics.policy.neutral)
    return radiance


def run(stack: ExposureStack, radiance: np.ndarray, repeats: int) -> list[dict]:
    response = true_response(stack.code_max, stack.codes.shape[-1])
    mask = well_exposed(stack.codes, stack.code_max)
    rows: list[dict] = []

    # The floor and both merges in turn, so that a drift in the machine's speed (it is
    # shared) falls on all three alike. The floor copies into a buffer it reuses; the
    # merges allocate their output each call, as a caller's merge does.
    destination = np.empty_like(stack.codes)
    # "inverse-variance" is the default estimator with its noise model fitted from the
    # codes inside the call (hdrio.radiometry.noise): what a merge costs now, against "log",
    # the kernel as it was before the noise model.
    timings = measure_alternately({
        "floor": lambda: parallel_copy(stack.codes, destination),
        "log": lambda: merge_brackets(stack, response, domain="log")[0],
        "linear": lambda: merge_brackets(stack, response, domain="linear")[0],
        "inverse-variance": lambda: MERGE_METHODS["inverse-variance"](stack, response)[0],
        # The saturation policies' cost: the per-channel policy at Z_max reads the codes
        # as they are; every other policy remaps each bracket's row first (the pixel
        # rule, limits below Z_max); "auto" also samples the codes for its white levels
        # and mixing test (hdrio.merge.saturation).
        "log, pixel rule": lambda: merge_brackets(stack, response, domain="log",
                                                  saturation="pixel")[0],
        "inverse-variance, channel saturation": lambda: MERGE_METHODS["inverse-variance"](
            stack, response, saturation="channel")[0],
        # --highlights reconstruct (hdrio.merge.highlights): the scene's clipped pixels
        # (0.06 %, 16 sun glints spread over the tiled frame) reconstructed after the merge.
        "inverse-variance, highlights reconstruct": lambda: reconstructed(stack, response),
    }, repeats)
    destination = None
    rows.append({"row": "merge", "method": "floor (copy of the codes, all cores)",
                 "seconds": timings["floor"].seconds, "peak_mb": timings["floor"].peak_mb})
    for domain in ("log", "linear", "inverse-variance", "log, pixel rule",
                   "inverse-variance, channel saturation",
                   "inverse-variance, highlights reconstruct"):
        timing = timings[domain]
        error = radiance_error(timing.result, radiance, mask)
        rows.append({"row": "merge", "method": f"hdrio merge ({domain})",
                     "seconds": timing.seconds, "peak_mb": timing.peak_mb,
                     "median_error": error["median"], "p99_error": error["p99"]})
        timing.result = None

    try:
        import cv2
    except ImportError:
        rows.append({"row": "merge", "method": "OpenCV MergeDebevec",
                     "skipped": "opencv-python-headless is not installed (the bench extra)"})
        return rows
    images = list(stack.codes)  # contiguous views, no copy
    times = np.asarray(stack.exposures, dtype=np.float32)
    cv_response = np.exp(response.log_inverse).astype(np.float32).reshape(-1, 1, 3)
    merge = cv2.createMergeDebevec()
    timing = measure_call(lambda: merge.process(images, times, cv_response), repeats,
                          warmup=1)
    error = radiance_error(timing.result, radiance, mask)
    rows.append({"row": "merge", "method": "OpenCV MergeDebevec", "seconds": timing.seconds,
                 "peak_mb": timing.peak_mb, "median_error": error["median"],
                 "p99_error": error["p99"]})
    return rows
