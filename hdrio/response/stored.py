"""Responses saved in an hdrio EXR header (``hdrio:response*``), read back for reuse.

A response recovered once (from a well-exposed set) can merge later sets shot with the
same camera settings: ``hdrio ... --response-from earlier.exr --merge``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from hdrio.errors import InputError
from hdrio.response.curve import CameraResponse
from hdrio.response.linear import linear_response

_RANGE = re.compile(r"(\w+) (\d+)-(\d+)")


def response_from_header(header: dict, source: str = "<header>") -> CameraResponse:
    """Rebuild the :class:`CameraResponse` written by :func:`hdrio.pipeline.exr_attributes`.

    Level ``k`` of the stored curves is code ``k * codeMax / (levels - 1)``; codes between
    levels are interpolated linearly in ``g`` (natural-log units). Raises
    :class:`InputError` naming ``source`` when the header holds no response.
    """
    try:
        code_max = int(header["hdrio:codeMax"])
        method = str(header.get("hdrio:responseMethod", "Debevec1997"))
    except KeyError:
        raise InputError(source, "holds no hdrio response (no hdrio:codeMax attribute); "
                                 "use an EXR written by hdrio") from None
    names = [name for name in "RGBY" if f"hdrio:response{name}" in header]
    if not names:
        raise InputError(source, "holds no hdrio response curves (hdrio:responseR/G/B)")
    if method == "linear":
        return linear_response(code_max, len(names))
    curves = [np.asarray(header[f"hdrio:response{name}"], dtype=np.float64).reshape(-1)
              for name in names]
    levels = curves[0].size
    position = np.arange(code_max + 1) * ((levels - 1) / code_max)
    g = np.stack([np.interp(position, np.arange(levels), curve) for curve in curves], axis=1)
    supported = np.ones_like(g, dtype=bool)
    for name, low, high in _RANGE.findall(str(header.get("hdrio:responseSupport", ""))):
        if name in names:
            codes = np.arange(code_max + 1)
            supported[:, names.index(name)] = (codes >= int(low)) & (codes <= int(high))
    return CameraResponse(g, code_max, supported, method=method,
                          parameters={"smoothing": float(header.get("hdrio:lambda", 0.0)),
                                      "weighting": str(header.get("hdrio:weighting", "n/a")),
                                      "sampling": f"from {source}", "samples": 0,
                                      "levels": levels})


def read_response(path: str | Path) -> CameraResponse:
    """The response stored in the header of ``path`` (an EXR written by hdrio)."""
    from hdrio.io.header import read_header

    return response_from_header(read_header(path), str(path))
