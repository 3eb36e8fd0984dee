"""Responses saved in an hdrio EXR header (``hdrio:response*``), read back for reuse.

A response recovered once (from a well-exposed set) can merge later sets shot with the
same camera settings: ``hdrio ... --response-from earlier.exr --merge``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from hdrio.errors import InputError
from hdrio.radiometry.curve import CameraResponse, linear_response
from hdrio.radiometry.levels import SPACINGS, level_of

_RANGE = re.compile(r"(\w+) (\d+)-(\d+)")


_MAX_LEVELS = 65536


def _code_max(header: dict, source: str) -> int:
    value = header.get("hdrio:codeMax")
    if value is None:
        raise InputError(source, "holds no hdrio response (no hdrio:codeMax attribute); "
                                 "use an EXR written by hdrio")
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        number = float("nan")
    if not np.isfinite(number) or number != int(number) or not 1 <= number < _MAX_LEVELS:
        raise InputError(source, f"hdrio:codeMax is {value!r}, not a code range (255 for "
                                 "8-bit, 65535 for 16-bit): not a response hdrio wrote")
    return int(number)


def _curve(header: dict, name: str, source: str) -> np.ndarray:
    attribute = f"hdrio:response{name}"
    value = header[attribute]
    try:
        curve = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        curve = np.empty(0)
    if not 2 <= curve.size <= _MAX_LEVELS or not np.all(np.isfinite(curve)):
        raise InputError(source, f"{attribute} is not a response curve (2 to {_MAX_LEVELS} "
                                 "finite numbers): not a response hdrio wrote")
    return curve


def _number(header: dict, name: str, default: float) -> float:
    try:
        value = float(header.get(name, default))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return default
    return value if np.isfinite(value) else default


def response_from_header(header: dict, source: str = "<header>") -> CameraResponse:
    """Rebuild the :class:`CameraResponse` written by :func:`hdrio.job.output.exr_attributes`.

    Level ``k`` of the stored curves is code ``k * codeMax / (levels - 1)``, or where
    ``hdrio:responseSpacing`` is ``sqrt`` code ``codeMax (k / (levels - 1))^2``
    (:func:`hdrio.radiometry.levels.code_of`); codes between levels are interpolated
    linearly in ``g`` (natural-log units). Raises
    :class:`InputError` naming ``source`` when the header holds no response, or one that
    is not well formed (code range, curves of finite numbers of one length).
    """
    code_max = _code_max(header, source)
    method = str(header.get("hdrio:responseMethod", "Debevec1997"))
    names = [name for name in "RGBY" if f"hdrio:response{name}" in header]
    if not names:
        raise InputError(source, "holds no hdrio response curves (hdrio:responseR/G/B)")
    if len(names) not in (1, 3) or (len(names) == 3 and "Y" in names):
        raise InputError(source, f"holds response curves {', '.join(names)}: expected R, G, "
                                 "B or Y alone")
    if method == "linear":
        return linear_response(code_max, len(names))
    curves = [_curve(header, name, source) for name in names]
    levels = curves[0].size
    if any(curve.size != levels for curve in curves):
        raise InputError(source, "its response curves differ in length: not a response "
                                 "hdrio wrote")
    spacing = str(header.get("hdrio:responseSpacing", "even"))  # even before it was written
    if spacing not in SPACINGS:
        raise InputError(source, f"hdrio:responseSpacing is {spacing!r}, not one of "
                                 f"{', '.join(SPACINGS)}: not a response hdrio wrote")
    position = level_of(np.arange(code_max + 1), code_max, levels, spacing)
    g = np.stack([np.interp(position, np.arange(levels), curve) for curve in curves], axis=1)
    supported = np.ones_like(g, dtype=bool)
    for name, low, high in _RANGE.findall(str(header.get("hdrio:responseSupport", ""))):
        if name in names:
            codes = np.arange(code_max + 1)
            supported[:, names.index(name)] = (codes >= int(low)) & (codes <= int(high))
    return CameraResponse(g, code_max, supported, method=method,
                          parameters={"smoothing": _number(header, "hdrio:lambda", 0.0),
                                      "weighting": str(header.get("hdrio:weighting", "n/a")),
                                      "sampling": f"from {source}", "samples": 0,
                                      "levels": levels, "spacing": spacing,
                                      "source": source})


def check_response_fits(response: CameraResponse, code_max: int, channels: int) -> None:
    """Refuse a saved response made for other brackets (bit depth, channel count), naming
    the file it came from and what to do."""
    source = response.parameters.get("source", "the saved response")
    bits = {255: "8-bit", 65535: "16-bit"}
    if response.code_max != code_max:
        raise InputError(source, f"the response is for codes 0..{response.code_max} "
                                 f"({bits.get(response.code_max, 'another bit depth')}), "
                                 f"the brackets are 0..{code_max} "
                                 f"({bits.get(code_max, 'another depth')}); use a response "
                                 "saved from brackets of the same bit depth")
    if response.channels != channels:
        raise InputError(source, f"the response has {response.channels} channel(s), the "
                                 f"brackets {channels}; use a response saved from "
                                 f"{'greyscale' if channels == 1 else 'colour'} brackets")


def read_response(path: str | Path) -> CameraResponse:
    """The response stored in the header of ``path`` (an EXR written by hdrio)."""
    from hdrio.io.header import read_header

    return response_from_header(read_header(path), str(path))
