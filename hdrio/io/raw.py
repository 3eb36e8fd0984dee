"""Camera RAW brackets through rawpy (LibRaw): linear sensor data, no tone curve.

OpenImageIO's wheel has no LibRaw, so RAW files (DNG, CR2, CR3, NEF, ARW, RAF, ORF, ...)
are decoded here. Each frame is demosaicked by LibRaw with

* black and white levels from the file, and no automatic brightening or maximum
  adjustment, so code values stay proportional to exposure across the set;
* one white balance for the whole set: as shot in the first file, or given;
* the file's camera-to-XYZ matrix (DNG ``ColorMatrix``, or LibRaw's table), output as
  linear CIE XYZ (D65) in 16-bit codes, no gamma.

Sensels at or above the saturation level (``SATURATION_FRACTION`` of the black-to-white
range), and the pixels the demosaic spreads them to, are set to the top code in every
channel, which the merge treats as saturated. A set decoded here carries
``RAW_SPACE = "XYZ"`` in each frame's metadata: the pipeline then uses the linear
response instead of solving one, and converts the merged XYZ to the working space.
"""

from __future__ import annotations

import datetime
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from hdrio.errors import InputError

RAW_SUFFIXES = frozenset({
    ".3fr", ".arw", ".cr2", ".cr3", ".crw", ".dcr", ".dng", ".erf", ".iiq", ".k25", ".kdc",
    ".mef", ".mos", ".mrw", ".nef", ".nrw", ".orf", ".pef", ".raf", ".raw", ".rw2", ".rwl",
    ".sr2", ".srf", ".srw", ".x3f",
})
RAW_SPACE = "hdrio:rawSpace"
RAW_CODE_MAX = 65535
# Real sensors clip a little below the nominal white level; treat the top 2 % as clipped.
SATURATION_FRACTION = 0.98
# AHD demosaic reads a 5x5 neighbourhood: a clipped sensel taints the pixels around it.
_DEMOSAIC_REACH = 2
# LibRaw's sizes.flip: 3 = 180 degrees, 5 = 90 counter-clockwise, 6 = 90 clockwise.
_ROTATIONS = {0: 0, 3: 2, 5: 1, 6: -1}


def is_raw(path: str | Path) -> bool:
    """Whether ``path`` has a camera RAW suffix (decoded through rawpy)."""
    return Path(path).suffix.lower() in RAW_SUFFIXES


def _rawpy(path: Path):
    """The rawpy module; a file's error where it is not installed (the ``raw`` extra: a
    plain install leaves LibRaw out)."""
    try:
        import rawpy
    except ImportError:
        raise InputError(path, "camera RAW needs rawpy (LibRaw), which a plain install "
                               "leaves out: pip install 'hdrio[raw]'") from None
    return rawpy


def _open(path: Path):
    rawpy = _rawpy(path)
    if not path.is_file():
        raise InputError(path, "no such file")
    try:
        return rawpy.imread(str(path))
    except (rawpy.LibRawError, OSError, ValueError) as error:
        raise InputError(path, f"cannot read camera RAW ({type(error).__name__}: "
                               f"{error or 'unsupported or damaged file'})") from None


def raw_exif(path: str | Path) -> dict:
    """``ExposureTime`` (s), ``FNumber``, ``ISO`` and ``DateTimeOriginal`` from a RAW file.

    ``DateTimeOriginal`` is EXIF text (``YYYY:MM:DD HH:MM:SS``); fields the file lacks
    are left out.
    """
    path = Path(path)
    with _open(path) as raw:
        # RawPy.other (shutter, aperture, ISO, time) is recent in rawpy (0.28 here); older
        # versions give no EXIF, and exposures then come from a sidecar or --exposures.
        other = getattr(raw, "other", None)
    exif: dict = {}
    if other is None:
        return exif
    for key, value in (("ExposureTime", other.shutter_speed), ("FNumber", other.aperture),
                       ("ISO", other.iso_speed)):
        if value and value > 0:
            exif[key] = float(value)
    stamp = other.timestamp
    if isinstance(stamp, datetime.datetime) and stamp.year > 1970:
        exif["DateTimeOriginal"] = stamp.strftime("%Y:%m:%d %H:%M:%S")
    return exif


def as_shot_white_balance(path: str | Path) -> tuple[float, float, float, float]:
    """The camera's as-shot white-balance multipliers (R, G, B, G2) of ``path``."""
    path = Path(path)
    with _open(path) as raw:
        multipliers = [float(v) for v in raw.camera_whitebalance]
    if not any(m > 0 for m in multipliers[:3]):
        raise InputError(path, "no as-shot white balance in the file; give one")
    if multipliers[3] <= 0:
        multipliers[3] = multipliers[1]
    return tuple(multipliers)  # type: ignore[return-value]


def read_raw(path: str | Path, white_balance: Sequence[float] | None = None
             ) -> tuple[np.ndarray, int, dict]:
    """Decode a RAW frame: ``(codes HxWx3 uint16 linear XYZ, 65535, exif)``.

    Parameters
    ----------
    path
        A camera RAW file LibRaw reads.
    white_balance
        Multipliers ``(R, G, B[, G2])``; default the file's as-shot values. A bracket set
        must share one (see :func:`read_raw_set`), or its frames would not be linear
        in one another.

    Codes are linear in exposure: ``(sensel - black) / (white - black)`` times the white
    balance, through the camera matrix, scaled to 16 bits. Saturated pixels are
    ``65535`` in every channel.
    """
    import scipy.ndimage

    path = Path(path)
    rawpy = _rawpy(path)
    wb = list(white_balance) if white_balance is not None else list(as_shot_white_balance(path))
    if len(wb) == 3:
        wb.append(wb[1])
    with _open(path) as raw:
        try:
            mosaic = raw.raw_image_visible
            black = float(np.mean(raw.black_level_per_channel))
            white = float(raw.white_level)
            clipped = mosaic >= black + SATURATION_FRACTION * (white - black)
            xyz = raw.postprocess(
                gamma=(1, 1), no_auto_bright=True, output_bps=16, user_wb=wb,
                output_color=rawpy.ColorSpace.XYZ, adjust_maximum_thr=0.0, user_flip=0,
                highlight_mode=rawpy.HighlightMode.Clip,
            )
            flip = int(raw.sizes.flip)
        except rawpy.LibRawError as error:
            raise InputError(path, f"cannot decode camera RAW ({error})") from None
    if clipped.shape != xyz.shape[:2]:
        raise InputError(path, f"RAW mosaic {clipped.shape} and image {xyz.shape[:2]} differ; "
                               "this camera's layout is not supported")
    if clipped.any():
        clipped = scipy.ndimage.binary_dilation(clipped, iterations=_DEMOSAIC_REACH)
        xyz[clipped] = RAW_CODE_MAX
    turns = _ROTATIONS.get(flip, 0)
    codes = np.ascontiguousarray(np.rot90(xyz, turns) if turns else xyz)
    exif = raw_exif(path)
    exif[RAW_SPACE] = "XYZ"
    exif["WhiteBalance"] = tuple(wb)
    return codes, RAW_CODE_MAX, exif


def read_raw_set(paths: Sequence[str | Path], white_balance: Sequence[float] | None = None,
                 progress: Callable[[int, int, str], None] | None = None
                 ) -> list[tuple[np.ndarray, int, dict]]:
    """Decode RAW brackets with one white balance: given, or the first file's as shot."""
    paths = [Path(p) for p in paths]
    wb = white_balance if white_balance is not None else as_shot_white_balance(paths[0])
    decoded = []
    for done, path in enumerate(paths, start=1):
        decoded.append(read_raw(path, wb))
        if progress:
            progress(done, len(paths), str(path))
    return decoded


def is_raw_stack(stack) -> bool:
    """Whether every frame of ``stack`` was decoded here (linear XYZ codes)."""
    return bool(stack.metadata) and all(m.get(RAW_SPACE) == "XYZ" for m in stack.metadata)
