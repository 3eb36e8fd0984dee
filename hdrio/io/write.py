"""Write images atomically with OpenImageIO: a temp file beside the target, then rename.

A crash, a full disk or an exception leaves either the previous file or none, never a
half-written EXR.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hdrio.errors import HdrioError

HALF_MAX = 65504.0
HALF_MIN_POSITIVE = 2.0**-24  # smallest positive (subnormal) half
_AGGREGATE_LENGTHS = (2, 3, 9, 16)


class OutputError(HdrioError):
    """An output could not be written (the message names the file)."""


@dataclass(frozen=True)
class Float2:
    """Two floats stored as an EXR ``v2f`` vector (e.g. ``adoptedNeutral``), not a list."""

    x: float
    y: float


def _type_of(value) -> tuple[str, object]:
    """The OpenImageIO type name and value for an attribute (scalars, strings, arrays)."""
    if isinstance(value, Float2):
        return "float2", (float(value.x), float(value.y))
    if isinstance(value, bool):
        return "int", int(value)
    if isinstance(value, int | np.integer):
        if not -(2**31) <= int(value) < 2**31:
            raise TypeError(f"integer {value} does not fit an EXR int attribute")
        return "int", int(value)
    if isinstance(value, float | np.floating):
        return "float", float(value)
    if isinstance(value, str):
        return "string", value
    if isinstance(value, np.ndarray | Sequence) and len(value) > 0:
        items = list(np.asarray(value).reshape(-1)) if isinstance(value, np.ndarray) else value
        if all(isinstance(item, str) for item in items):
            return f"string[{len(items)}]", tuple(items)
        if all(isinstance(item, int | np.integer) for item in items):
            # OpenImageIO's EXR writer keeps int lists only as 2- or 3-vectors.
            raise TypeError("integer lists have no EXR attribute type; store floats or text")
        if len(items) in _AGGREGATE_LENGTHS:
            # float[2|3|9|16] would become v2f/v3f/m33f/m44f, not a list.
            raise TypeError(f"a list of {len(items)} floats would be stored as a vector or "
                            "matrix; store it as text")
        return f"float[{len(items)}]", tuple(float(item) for item in items)
    raise TypeError(f"cannot store attribute value {value!r}")


_ROWS_PER_WRITE = 64


def _temporary_beside(path: Path) -> Path:
    """A hidden temporary name in ``path``'s folder (same file system: rename is atomic)."""
    return path.with_name(f".{path.stem}.{uuid.uuid4().hex[:8]}.partial{path.suffix}")


def write_image(path: str | Path, pixels: np.ndarray, pixel_type: str,
                attributes: Mapping[str, object] | None = None,
                band: Callable[[np.ndarray], np.ndarray] | None = None,
                channel_names: Sequence[str] | None = None) -> Path:
    """Write ``pixels`` (H x W x C) to ``path`` atomically; the format follows the suffix.

    Rows go out in bands of 64, each through ``band`` first when given (a conversion
    applied band by band needs no full-size copy of the image). ``pixels`` may be any
    object with ``shape`` whose row slices are arrays. ``channel_names`` replaces
    OpenImageIO's defaults (``R, G, B, A``, ...).
    """
    import OpenImageIO as oiio

    path = Path(path)
    if not path.parent.is_dir():
        raise OutputError(f"{path}: folder {path.parent} does not exist")
    height, width, channels = pixels.shape
    spec = oiio.ImageSpec(width, height, channels, pixel_type)
    if channel_names is not None:
        spec.channelnames = tuple(channel_names)
    for name, value in (attributes or {}).items():
        type_name, stored = _type_of(value)
        spec.attribute(name, oiio.TypeDesc(type_name), stored)
    temp = _temporary_beside(path)
    try:
        output = oiio.ImageOutput.create(str(temp))
        if output is None:
            raise OutputError(f"{path}: cannot write this format ({oiio.geterror().strip()})")
        try:
            if not output.open(str(temp), spec):
                raise OutputError(f"{path}: write failed ({output.geterror().strip()})")
            for top in range(0, height, _ROWS_PER_WRITE):
                rows = pixels[top: top + _ROWS_PER_WRITE]
                rows = np.ascontiguousarray(band(rows) if band is not None else rows)
                if not output.write_scanlines(top, top + rows.shape[0], 0, rows):
                    raise OutputError(f"{path}: write failed ({output.geterror().strip()})")
        finally:
            output.close()
        os.replace(temp, path)
    finally:
        if temp.exists():
            temp.unlink()
    return path


class _WithLayers:
    """RGB rows with extra one-channel layers appended, a band at a time (no copy)."""

    def __init__(self, rgb: np.ndarray, layers: list[np.ndarray]) -> None:
        self.rgb, self.layers = rgb, layers
        self.shape = (*rgb.shape[:2], rgb.shape[2] + len(layers))

    def __getitem__(self, rows: slice) -> np.ndarray:
        return np.concatenate([np.asarray(self.rgb[rows], np.float32)]
                              + [layer[rows, :, None] for layer in self.layers], axis=-1)


def write_exr(path: str | Path, rgb: np.ndarray, attributes: Mapping[str, object] | None = None,
              pixel_type: str = "half", compression: str = "zip", scale: float = 1.0,
              layers: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write scene-linear RGB as OpenEXR (half by default), ZIP-compressed, atomically.

    ``scale`` multiplies the pixels on the way out (band by band: ``rgb`` is not copied
    or changed). Half floats hold 2**-24 .. 65504: values beyond are clamped into that
    range (so no pixel becomes 0 or Inf); callers keep radiance inside it (see
    :func:`hdrio.pipeline.half_safe_scale`). ``layers`` (channel name, e.g.
    ``motion.Y``, to an ``(H, W)`` array of values in [0, 1]) are written after R, G, B,
    unscaled.
    """
    if pixel_type not in ("half", "float"):
        raise ValueError(f"EXR pixel type must be 'half' or 'float', not {pixel_type!r}")
    factor = np.float32(scale)

    def band(rows: np.ndarray) -> np.ndarray:
        rows = np.array(rows, dtype=np.float32)
        colour = rows[..., :rgb.shape[2]]
        if factor != 1:
            colour *= factor
        if pixel_type == "half":
            np.clip(colour, HALF_MIN_POSITIVE, HALF_MAX, out=colour)
        return rows

    attributes = {"compression": compression, **(attributes or {})}
    if not layers:
        return write_image(path, rgb, pixel_type, attributes, band)
    names = (["R", "G", "B"] if rgb.shape[2] == 3 else ["Y"]) + list(layers)
    return write_image(path, _WithLayers(rgb, list(layers.values())), pixel_type, attributes,
                       band, channel_names=names)


def write_preview(path: str | Path, display_rgb: np.ndarray) -> Path:
    """Write display-referred RGB in [0, 1] (already encoded) as an 8-bit image."""
    codes = np.round(np.clip(display_rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
    return write_image(path, codes, "uint8")


def write_text(path: str | Path, text: str) -> Path:
    """Write a UTF-8 text file (an OCIO config, a LUT) atomically."""
    path = Path(path)
    if not path.parent.is_dir():
        raise OutputError(f"{path}: folder {path.parent} does not exist")
    temp = _temporary_beside(path)
    try:
        temp.write_text(text, encoding="utf-8")
        os.replace(temp, path)
    except OSError as error:
        raise OutputError(f"{path}: write failed ({error.strerror})") from None
    finally:
        if temp.exists():
            temp.unlink()
    return path
