"""Write synthetic DNG files (a Bayer mosaic of known linear radiance) with tifffile.

The tags are the ones LibRaw needs to decode a DNG: CFA layout and pattern, black and
white levels, ``ColorMatrix1`` (XYZ to camera) with its illuminant, ``AsShotNeutral``, and
the exposure time and capture time for EXIF.

The camera is linear sRGB scaled per channel by ``NEUTRAL``: a camera channel records
``NEUTRAL[c] * E_c`` for scene-linear Rec.709 radiance ``E``. Its ``ColorMatrix1`` is
therefore ``diag(NEUTRAL) @ M_XYZ_to_sRGB``, and white balancing by ``1 / NEUTRAL`` (as
shot) gives back ``E``: the merged, colour-converted image should equal the truth.
"""

from __future__ import annotations

import datetime
from fractions import Fraction
from pathlib import Path

import numpy as np

NEUTRAL = np.array([0.5, 1.0, 0.7])  # camera response to white, like a daylight Bayer sensor
BLACK, WHITE = 512, 16383  # a 14-bit sensor with a black pedestal
RGGB = np.array([[0, 1], [1, 2]])


def _rationals(values, denominator: int = 1_000_000) -> list[int]:
    out: list[int] = []
    for value in values:
        out += [int(round(value * denominator)), denominator]
    return out


def mosaic_of(radiance: np.ndarray, exposure: float, neutral=NEUTRAL, gain: float = 1.0
              ) -> np.ndarray:
    """Raw sensel values (uint16, RGGB) of ``radiance`` (H x W x 3) exposed ``exposure`` s.

    Sensor signal ``X = gain * neutral[c] * E_c * t`` clips at 1 (full well), then maps to
    ``BLACK .. WHITE`` and is rounded: linear, no noise.
    """
    height, width, _ = radiance.shape
    colour = np.tile(RGGB, (height // 2, width // 2))
    values = np.take_along_axis(radiance, colour[..., None], axis=2)[..., 0]
    signal = gain * np.asarray(neutral)[colour] * values * exposure
    return np.rint(BLACK + np.clip(signal, 0.0, 1.0) * (WHITE - BLACK)).astype(np.uint16)


def write_dng(path: Path, mosaic: np.ndarray, exposure: float, neutral=NEUTRAL,
              captured: datetime.datetime | None = None) -> Path:
    """Write ``mosaic`` as a DNG 1.4 with the tags LibRaw reads (see the module notes)."""
    import colour
    import tifffile

    xyz_to_camera = np.diag(neutral) @ colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB
    ratio = Fraction(exposure).limit_denominator(1_000_000)
    stamp = (captured or datetime.datetime(2026, 1, 1, 12, 0, 0)).strftime("%Y:%m:%d %H:%M:%S")
    tags = [
        (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
        (50708, "s", 0, "hdrio synthetic", True),  # UniqueCameraModel
        (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, "B", 4, tuple(RGGB.reshape(-1)), True),  # CFAPattern
        (50714, "H", 1, (BLACK,), True),  # BlackLevel
        (50717, "H", 1, (WHITE,), True),  # WhiteLevel
        (50721, "2i", 9, _rationals(xyz_to_camera.reshape(-1)), True),  # ColorMatrix1
        (50778, "H", 1, (21,), True),  # CalibrationIlluminant1: D65
        (50728, "2I", 3, _rationals(neutral), True),  # AsShotNeutral
        (33434, "2I", 1, (ratio.numerator, ratio.denominator), True),  # ExposureTime
        (306, "s", 0, stamp, True),  # DateTime
        (271, "s", 0, "hdrio", True),  # Make
        (272, "s", 0, "synthetic", True),  # Model
    ]
    tifffile.imwrite(path, mosaic, photometric="cfa", extratags=tags)
    return Path(path)
