"""The response of a linear sensor (camera RAW, linear TIFF): nothing to solve.

A linear sensor's code is proportional to exposure up to its saturation level, so
``f^-1(z) = z / z_mid`` and ``g(z) = ln(z / z_mid)``, with ``g(z_mid) = 0`` as for every
hdrio response (``z_mid = (code_max + 1) // 2``). Code 0 carries no exposure estimate and
is marked unsupported, so the merge gives it no weight.
"""

from __future__ import annotations

from hdrio.radiometry.curve import CameraResponse, linear_response


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
