"""Write images atomically with OpenImageIO: a temp file beside the target, then rename.

A crash, a full disk or an exception leaves either the previous file or none, never a
half-written EXR. This module owns the temp names (:func:`temporary_name`): hidden,
``.<stem>.<8 hex>.partial<suffix>``, the stem shortened so that the name fits the file
system's limit whenever the output's own name does.
"""

from __future__ import annotations

import contextlib
import os
import re
import socket
import uuid
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hdrio.errors import OutputError, library_message
from hdrio.io.native import size_thread_pools
from hdrio.parallel import read_ahead, row_bands, threads

HALF_MAX = 65504.0
EXR_COMPRESSIONS = ("none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa",
                    "dwab")
"""OpenEXR's compressions, as ``--compression`` names them (``dwaa:45`` sets a level)."""
HALF_MIN_POSITIVE = 2.0**-24  # smallest positive (subnormal) half
_AGGREGATE_LENGTHS = (2, 3, 9, 16)


@dataclass(frozen=True)
class Window:
    """Where an image's pixels lie in its frame (OpenEXR's data and display windows):
    the first pixel at ``(x, y)`` of a frame ``full_width x full_height`` whose corner is
    ``(full_x, full_y)``. A crop, or a render with overscan, keeps its place in the plate
    it belongs to."""

    x: int
    y: int
    full_x: int
    full_y: int
    full_width: int
    full_height: int

    @classmethod
    def of(cls, spec) -> Window | None:
        """An OpenImageIO spec's window; ``None`` where the pixels are the whole frame."""
        window = cls(spec.x, spec.y, spec.full_x, spec.full_y, spec.full_width,
                     spec.full_height)
        plain = cls(0, 0, 0, 0, spec.width, spec.height)
        return None if window == plain else window

    def __str__(self) -> str:
        return f"at ({self.x}, {self.y}) of a {self.full_width}x{self.full_height} frame"

    def scaled(self, x_factor: float, y_factor: float) -> Window:
        """The window of the image resized by these factors (the frame with it)."""
        return Window(round(self.x * x_factor), round(self.y * y_factor),
                      round(self.full_x * x_factor), round(self.full_y * y_factor),
                      max(1, round(self.full_width * x_factor)),
                      max(1, round(self.full_height * y_factor)))


@dataclass(frozen=True)
class Typed:
    """An attribute value with its OpenImageIO type name (``"float[3]"``, ``"rational2i"``),
    as read from another file: written back with the same type."""

    type: str
    value: object


@dataclass(frozen=True)
class Float2:
    """Two floats stored as an EXR ``v2f`` vector (e.g. ``adoptedNeutral``), not a list."""

    x: float
    y: float


def _type_of(value) -> tuple[str, object]:
    """The OpenImageIO type name and value for an attribute (scalars, strings, arrays)."""
    if isinstance(value, Float2):
        return "float2", (float(value.x), float(value.y))
    if isinstance(value, Typed):
        return value.type, value.value
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


def rows_per_write() -> int:
    """Rows handed to the writer at once: one of OpenEXR's 16-row ZIP blocks per thread
    of the budget, at least four (64 rows), so that every thread of its pool compresses a
    block of each band. Each band is converted on every thread (:func:`to_half`), so it
    need not be larger: at 16 threads four blocks a thread (1024 rows, 37 MB of half RGB
    at 6000 wide, three bands in flight) held 100 MB more than one."""
    return 16 * max(4, threads())


# The writer's host (letters, digits and '-') and process id are in the temporary name,
# so a later run can prove a leftover is stale (its writer is dead): hdrio.batch.partial.
_HOST = re.sub(r"[^A-Za-z0-9-]", "-", socket.gethostname()) or "host"
TEMPORARY_NAME = re.compile(r"^\.(?P<stem>.*)\.(?P<host>[A-Za-z0-9-]+)-(?P<pid>\d+)"
                            r"-[0-9a-f]{8}\.partial(?P<suffix>\.[^.]*)?$")


def temporary_writer(path: str | Path) -> tuple[str, int] | None:
    """``(host, pid)`` of the process writing the temporary file ``path``, or ``None``
    when the name is not one of hdrio's temporary names."""
    match = TEMPORARY_NAME.match(Path(path).name)
    return (match["host"], int(match["pid"])) if match else None


def this_writer() -> tuple[str, int]:
    """``(host, pid)`` as this process puts them in its temporary names."""
    return _HOST, os.getpid()


NAME_MAX = 255  # bytes in one file name (Linux, macOS, Windows)
PARTIAL = ".partial"


def temporary_name(path: str | Path, token: str | None = None) -> Path:
    """A hidden temp name beside ``path`` (same file system: the rename is atomic).

    ``.<stem>.<token>.partial<suffix>`` (:data:`TEMPORARY_NAME`), ``token`` the writer's
    ``host-pid`` and 8 random hex digits; the stem is cut (on a character boundary) so
    the name stays within :data:`NAME_MAX` bytes.
    """
    path = Path(path)
    token = token or f"{_HOST}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    tail = f".{token}{PARTIAL}{path.suffix}"
    room = NAME_MAX - 1 - len(os.fsencode(tail))
    stem = os.fsencode(path.stem)[:max(room, 0)].decode(errors="ignore")
    return path.with_name(f".{stem}{tail}")


def is_temporary_of(path: str | Path, candidate: str | Path) -> bool:
    """Whether ``candidate`` is a temp name :func:`temporary_name` gives for ``path``."""
    path, candidate = Path(path), Path(candidate)
    name = candidate.name
    if candidate.parent != path.parent or not name.endswith(PARTIAL + path.suffix):
        return False
    stem, _, token = name[1:-len(PARTIAL + path.suffix)].rpartition(".")
    return (TEMPORARY_NAME.match(name) is not None
            and temporary_name(path, token).name == name)


def _os_problem(error: OSError) -> str:
    return (error.strerror or str(error)).lower()


def _claim(path: Path) -> Path:
    """Create the temp file for ``path`` (exclusively), or say why the folder refuses it."""
    if not path.parent.is_dir():
        raise OutputError(f"{path}: folder {path.parent} does not exist")
    temp = temporary_name(path)
    try:
        os.close(os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    except OSError as error:
        raise OutputError(f"{path}: cannot write in {path.parent} ({_os_problem(error)})"
                          ) from None
    return temp


def _discard(temp: Path) -> None:
    """Remove a temp file; never masks the error being raised."""
    with contextlib.suppress(OSError):
        os.unlink(temp)


def check_writable(path: str | Path) -> None:
    """Raise :class:`OutputError` unless a file can be created beside ``path`` (its
    folder exists and takes a new file: permissions, read-only file system, name length).

    The probe is the writer's own temp name, created and removed at once.
    """
    _discard(_claim(Path(path)))


def _publish(temp: Path, path: Path) -> None:
    try:
        os.replace(temp, path)
    except OSError as error:
        raise OutputError(f"{path}: cannot replace it ({_os_problem(error)})") from None


def write_image(path: str | Path, pixels: np.ndarray, pixel_type: str,
                attributes: Mapping[str, object] | None = None,
                band: Callable[[np.ndarray], np.ndarray] | None = None,
                channel_names: Sequence[str] | None = None,
                window: Window | None = None) -> Path:
    """Write ``pixels`` (H x W x C) to ``path`` atomically; the format follows the suffix.

    Rows go out in bands (:func:`rows_per_write`), each through ``band`` first when given
    (a conversion applied band by band needs no full-size copy of the image). ``pixels`` may be any
    object with ``shape`` whose row slices are arrays. ``channel_names`` replaces
    OpenImageIO's defaults; one channel is named ``Y`` (OpenEXR's luminance). ``window``
    places the pixels in a larger frame (OpenEXR's data and display windows).
    """
    import OpenImageIO as oiio

    size_thread_pools()
    path = Path(path)
    height, width, channels = pixels.shape
    spec = oiio.ImageSpec(width, height, channels, pixel_type)
    if channel_names is not None:
        spec.channelnames = tuple(channel_names)
    elif channels == 1:
        spec.channelnames = ("Y",)
    if window is not None:
        spec.x, spec.y = window.x, window.y
        spec.full_x, spec.full_y = window.full_x, window.full_y
        spec.full_width, spec.full_height = window.full_width, window.full_height
    for name, value in (attributes or {}).items():
        type_name, stored = _type_of(value)
        spec.attribute(name, oiio.TypeDesc(type_name), stored)
    temp = _claim(path)
    try:
        output = oiio.ImageOutput.create(str(temp))
        if output is None:
            raise OutputError(f"{path}: cannot write this format "
                              f"({library_message(oiio.geterror)})")
        try:
            if not output.open(str(temp), spec):
                raise OutputError(f"{path}: write failed ({library_message(output.geterror)})")
            def bands():
                step = rows_per_write()
                for top in range(0, height, step):
                    rows = pixels[top: top + step]
                    yield top, np.ascontiguousarray(band(rows) if band is not None else rows)

            # The next band is converted (and observed) while this one is compressed.
            for top, rows in read_ahead(bands()):
                first = spec.y + top  # in the frame's rows
                if not output.write_scanlines(first, first + rows.shape[0], 0, rows):
                    raise OutputError(f"{path}: write failed ({library_message(output.geterror)})")
        finally:
            output.close()
        _publish(temp, path)
    finally:
        _discard(temp)
    return path


class _WithLayers:
    """The image's rows with extra ``(H, W, k)`` layers appended, a band at a time (no
    full-size copy)."""

    def __init__(self, rgb: np.ndarray, layers: list[np.ndarray]) -> None:
        self.rgb, self.layers = rgb, layers
        self.shape = (*rgb.shape[:2], rgb.shape[2] + sum(layer.shape[2] for layer in layers))

    def __getitem__(self, rows: slice) -> np.ndarray:
        return np.concatenate([np.asarray(self.rgb[rows], np.float32)]
                              + [np.asarray(layer[rows], np.float32) for layer in self.layers],
                              axis=-1)


def lossy_compression(compression: str, pixel_type: str) -> bool:
    """Whether OpenEXR's ``compression`` (:func:`exr_compression`'s name) changes the
    pixel values of a ``pixel_type`` (``half``, ``float``) image: DWAA and DWAB always
    (a DCT of the colour channels); B44 and B44A for half (they pack half channels'
    4 x 4 blocks, and leave float ones whole); PXR24 for float (it keeps 24 bits of 32,
    and half whole)."""
    name = compression.partition(":")[0]
    return name in ("dwaa", "dwab") or (name in ("b44", "b44a") and pixel_type == "half") \
        or (name == "pxr24" and pixel_type == "float")


def exr_compression(text: str) -> str:
    """``text`` as an EXR compression (:data:`EXR_COMPRESSIONS`, any case, an optional
    ``:LEVEL``), lower-cased; raises ``ValueError`` listing the choices."""
    name, _, level = text.lower().partition(":")
    if name not in EXR_COMPRESSIONS or (level and not level.isdigit()):
        raise ValueError(f"{text!r}: choose from {', '.join(EXR_COMPRESSIONS)}")
    return text.lower()


def write_exr(path: str | Path, rgb: np.ndarray, attributes: Mapping[str, object] | None = None,
              pixel_type: str = "half", compression: str = "zip", scale: float = 1.0,
              layers: Mapping[str, np.ndarray] | None = None,
              observe: Callable[[np.ndarray], None] | None = None,
              positive: bool = True,
              channels: Mapping[str, np.ndarray] | None = None,
              window: Window | None = None) -> Path:
    """Write scene-linear RGB as OpenEXR (half by default), ZIP-compressed, atomically.

    ``scale`` multiplies the pixels on the way out (band by band: ``rgb`` is not copied
    or changed). Half floats hold 2**-24 .. 65504: values beyond are clamped into that
    range (so no pixel of a merge's radiance becomes 0 or Inf; negative values, colours
    outside the output's gamut, are kept down to -65504); callers keep radiance inside it
    (see :func:`hdrio.job.output.half_safe_scale`). ``positive`` false also keeps zeros
    (another program's image, a tone-mapped one). ``observe(rows)``, when given, sees the
    image's own channels exactly as stored, piece by piece (a half image's as
    ``float16``), possibly from several threads at once.

    ``layers``: extra images of the same size (``(H, W, k)``), written unscaled as the
    channels ``name.R``, ``name.G``, ``name.B`` (``name.Y`` for one channel) after the
    image's own; ``channels``: single channels (``(H, W, 1)``) written unscaled under
    their own names after those (an input's layers, :func:`hdrio.io.images.read_layout`);
    ``window``: the pixels' place in a larger frame (:class:`Window`).
    """
    if pixel_type not in ("half", "float"):
        raise ValueError(f"EXR pixel type must be 'half' or 'float', not {pixel_type!r}")
    factor = np.float32(scale)
    own = rgb.shape[-1]
    colour = 3 if own >= 3 else 1  # RGB or Y, then alpha (grey with alpha: Y, A)
    names = (["R", "G", "B"] if colour == 3 else ["Y"]) + ["A"] * (own - colour)
    planes = [rgb]
    for name, layer in (layers or {}).items():
        layer = layer if layer.ndim == 3 else layer[..., None]
        planes.append(layer)
        names += [f"{name}.{c}" for c in ("RGB" if layer.shape[-1] == 3 else "Y")]
    for name, channel in (channels or {}).items():
        planes.append(channel)
        names.append(name)
    # As half: the image's own channels scaled, a merge's colour from 0 up raised to
    # half's smallest subnormal (no pixel becomes 0; a negative value, a colour outside
    # the output's gamut, stays negative, as a float EXR keeps it), alpha at least 0
    # (alpha 0 stays 0, e.g. pixels masked everywhere: hdrio.merge.exclusion), the
    # layers unscaled and kept finite.
    count = len(names)
    scales = [float(factor)] * own + [1.0] * (count - own)
    lows = [-HALF_MAX] * colour + [0.0] * (own - colour) + [-HALF_MAX] * (count - own)
    floors = [HALF_MIN_POSITIVE if positive else 0.0] * colour + [0.0] * (count - colour)
    highs = [HALF_MAX] * count

    def band(rows: np.ndarray) -> np.ndarray:
        if pixel_type == "half":  # on every core, each piece observed where it is made
            from hdrio.io.half import to_half  # numba: only for half EXRs

            return to_half(rows, scales, lows, highs, observe and (lambda done: observe(
                done[..., :own])), floors)
        rows = np.array(rows, dtype=np.float32)
        if factor != 1:
            rows[..., :own] *= factor
        if observe is not None:
            observe(rows[..., :own])
        return rows

    # No capture time known is none written: OpenImageIO stamps the time of writing as
    # capDate (the capture's date, to OpenEXR) where DateTime is absent.
    attributes = {"compression": compression, "DateTime": "", **(attributes or {})}
    image = rgb if len(planes) == 1 else _WithLayers(rgb, planes[1:])
    return write_image(path, image, pixel_type, attributes, band, channel_names=names,
                       window=window)


def write_preview(path: str | Path, display_rgb: np.ndarray) -> Path:
    """Write display-referred RGB in [0, 1] (already encoded) as an 8-bit image."""
    values = np.asarray(display_rgb)
    codes = np.empty(values.shape, np.uint8)
    bands = row_bands(values)
    for top in bands:  # no full-size temporaries: hdrio.parallel.ROWS_OF_VALUES
        rows = values[top:top + bands.step]
        codes[top:top + bands.step] = np.round(np.clip(rows, 0.0, 1.0) * 255.0)
    return write_image(path, codes, "uint8")


def write_text(path: str | Path, text: str) -> Path:
    """Write a UTF-8 text file (an OCIO config, a LUT) atomically."""
    path = Path(path)
    temp = _claim(path)
    try:
        temp.write_text(text, encoding="utf-8")
        _publish(temp, path)
    except OSError as error:
        raise OutputError(f"{path}: write failed ({_os_problem(error)})") from None
    finally:
        _discard(temp)
    return path
