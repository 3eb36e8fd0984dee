"""The response of a linear sensor (camera RAW, linear TIFF): nothing to solve.

A linear sensor's code is proportional to exposure up to its saturation level, so
``f^-1(z) = z / z_mid`` and ``g(z) = ln(z / z_mid)``, with ``g(z_mid) = 0`` as for every
hdrio response (``z_mid = (code_max + 1) // 2``). Code 0 carries no exposure estimate and
is marked unsupported, so the merge gives it no weight.
"""

from __future__ import annotations

import numpy as np

from hdrio.response.curve import CameraResponse


def response_linear(stack, **_ignored) -> CameraResponse:
    """The linear response for ``stack``'s code range and channel count.

    Parameters
    ----------
    stack
        An :class:`~hdrio.stack.ExposureStack` of linear code values (RAW sensor data
        after black subtraction, or linear 16-bit TIFF).
    **_ignored
        The solve options other methods take (``smoothing``, ``weighting``, ...): a linear
        response has none, so the registry can call every method the same way.

    Returns
    -------
    CameraResponse
        ``g(z) = ln(z / z_mid)`` per channel, in natural-log units of relative exposure.
    """
    return linear_response(int(stack.code_max), int(stack.codes.shape[-1]))


def linear_response(code_max: int, channels: int) -> CameraResponse:
    """``g(z) = ln(z / z_mid)`` for codes ``0..code_max``, ``channels`` identical columns."""
    z = np.arange(code_max + 1, dtype=np.float64)
    z_mid = (code_max + 1) // 2
    g = np.log(np.maximum(z, 0.5) / z_mid)
    supported = np.broadcast_to((z > 0)[:, None], (code_max + 1, channels)).copy()
    return CameraResponse(
        log_inverse=np.repeat(g[:, None], channels, axis=1), code_max=code_max,
        supported=supported, method="linear",
        # The header stores g at 1024 levels at most; read back, a "linear" response is
        # rebuilt exactly (see hdrio.response.stored), so nothing is lost.
        parameters={"smoothing": 0.0, "weighting": "n/a", "sampling": "n/a", "samples": 0,
                    "levels": min(code_max + 1, 1024)},
    )
