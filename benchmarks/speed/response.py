"""Response recovery: hdrio's Debevec 1997 solve against OpenCV's CalibrateDebevec.

Both with their default settings on the same brackets; the error column is the RMS of
``ln f^-1`` against the true curve, in stops (``benchmarks.truth.metrics``).
"""

from __future__ import annotations

import numpy as np

from benchmarks.speed.scene import GAMMA
from benchmarks.timing import measure_call
from benchmarks.truth.metrics import response_rms_stops
from hdrio.response import response_Debevec1997
from hdrio.stack import ExposureStack


def run(stack: ExposureStack, repeats: int) -> list[dict]:
    rows: list[dict] = []
    timing = measure_call(lambda: response_Debevec1997(stack), repeats, warmup=1)
    rms, _ = response_rms_stops(timing.result.log_inverse, GAMMA, stack.code_max)
    rows.append({"row": "response", "method": "hdrio response_Debevec1997 (defaults)",
                 "seconds": timing.seconds, "peak_mb": timing.peak_mb,
                 "response_rms_stops": rms})
    try:
        import cv2
    except ImportError:
        rows.append({"row": "response", "method": "OpenCV CalibrateDebevec",
                     "skipped": "opencv-python-headless is not installed (the bench extra)"})
        return rows
    images = list(stack.codes)
    times = np.asarray(stack.exposures, dtype=np.float32)
    calibrate = cv2.createCalibrateDebevec()
    timing = measure_call(lambda: calibrate.process(images, times), repeats, warmup=1)
    with np.errstate(divide="ignore"):
        log_inverse = np.log(timing.result.reshape(-1, 3).astype(np.float64))
    rms, _ = response_rms_stops(log_inverse, GAMMA, stack.code_max)
    rows.append({"row": "response", "method": "OpenCV CalibrateDebevec (defaults)",
                 "seconds": timing.seconds, "peak_mb": timing.peak_mb,
                 "response_rms_stops": rms})
    return rows
