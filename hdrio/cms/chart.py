"""The ColorChecker 24 check of ``hdrio check --chart``: each patch's CIE Delta E 2000
against colour-science's reference values, after one exposure fitted on the neutral row."""

from __future__ import annotations

import numpy as np

from hdrio.cms.calibration import Region
from hdrio.errors import HdrioError
from hdrio.radiometry.luminance import normalised_primary_matrix

COLORCHECKER = "ColorChecker24 - After November 2014"
NEUTRAL_PATCHES = slice(18, 24)  # white 9.5 .. black 2, the chart's bottom row


def check_chart_region(region: Region, width: int, height: int) -> None:
    """Raise unless the 6 x 4 chart ``region`` lies inside a ``width x height`` image."""
    x, y, w, h = region
    if w < 12 or h < 8 or x < 0 or y < 0 or x + w > width or y + h > height:
        raise HdrioError(f"chart region {x},{y},{w},{h} must lie inside the {width}x{height} "
                         "image and span at least 2 pixels per patch")


def chart_patches(rgb: np.ndarray, region: Region) -> np.ndarray:
    """Mean RGB ``(24, 3)`` of the central half of each patch of a 6 x 4 chart region.

    Patches in reading order, dark skin at top left, black at bottom right.
    """
    x, y, w, h = region
    check_chart_region(region, rgb.shape[1], rgb.shape[0])
    means = []
    for row in range(4):
        for column in range(6):
            left, right = x + (column + 0.25) * w / 6, x + (column + 0.75) * w / 6
            top, bottom = y + (row + 0.25) * h / 4, y + (row + 0.75) * h / 4
            patch = rgb[int(top): max(int(bottom), int(top) + 1),
                        int(left): max(int(right), int(left) + 1)]
            means.append(patch.reshape(-1, 3).astype(np.float64).mean(axis=0))
    return np.asarray(means)


def chart_delta_E(rgb: np.ndarray, region: Region, chromaticities: tuple[float, ...]
                  ) -> list[float]:
    """CIE Delta E 2000 of each ColorChecker patch against colour-science's reference.

    Exposure is unknown, so measured ``XYZ`` is first scaled (least squares on ``Y`` of
    the six neutral patches) to the reference. Both sides go to CIE Lab under the file's
    white; the reference (D50) is adapted to it with Bradford.
    """
    import colour

    measured = chart_patches(rgb, region) @ normalised_primary_matrix(chromaticities).T
    chart = colour.CCS_COLOURCHECKERS[COLORCHECKER]
    white = np.asarray(chromaticities[6:8], dtype=np.float64)
    reference = colour.chromatic_adaptation(
        colour.xyY_to_XYZ(np.asarray(list(chart.data.values()))),
        colour.xy_to_XYZ(chart.illuminant), colour.xy_to_XYZ(white), method="Von Kries",
        transform="Bradford")
    Y_m, Y_r = measured[NEUTRAL_PATCHES, 1], reference[NEUTRAL_PATCHES, 1]
    scale = float(np.dot(Y_m, Y_r) / np.dot(Y_m, Y_m))
    if not np.isfinite(scale) or scale <= 0:
        raise HdrioError("chart region: the neutral patches have no light")
    lab_measured = colour.XYZ_to_Lab(measured * scale, white)
    lab_reference = colour.XYZ_to_Lab(reference, white)
    return [float(v) for v in colour.delta_E(lab_measured, lab_reference, method="CIE 2000")]
