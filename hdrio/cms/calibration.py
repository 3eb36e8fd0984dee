"""Absolute luminance: scale relative radiance to cd/m^2, from EXIF or a user reference.

EXIF (the reflected-light meter equation, ISO 2720)
    A camera set to f-number ``N``, exposure time ``t`` (s) and ISO speed ``S`` is
    exposed correctly for a scene of average luminance ``L_avg = K N^2 / (t S)`` cd/m^2,
    ``K`` the meter calibration constant (12.5 by default, Canon/Nikon/Sekonic). A
    correctly exposed camera renders that luminance at its standard output level:
    code 118 of 255 (sRGB 18 % grey, the ISO 12232 standard output sensitivity point;
    ``118/255 * code_max`` for 16-bit). So a pixel of hdrio radiance ``E`` (with
    ``E * e_j = f^-1(Z)`` for the stack's exposure ``e_j``) has luminance
    ``Y(E) * L_avg_j * e_j / Y(f^-1(z_ref))``. The factor ``L_avg_j * e_j`` is the same
    for every bracket whatever unit ``e_j`` is in (seconds, or ``t * ISO/100 / N^2``).

Reference
    ``luminance``: the mean luminance of a region in cd/m^2 (a spot meter reading);
    ``illuminance`` and ``reflectance``: a diffuse grey card of that reflectance (0..1)
    under that illuminance (lux) has ``L = reflectance * illuminance / pi`` cd/m^2.

Without calibration the radiance stays relative (``E * dt = f^-1(Z)``, ``g(z_mid) = 0``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hdrio.errors import HdrioError, InputError
from hdrio.radiometry.luminance import luminance

if TYPE_CHECKING:  # annotations only: importing the response solver costs a second
    from hdrio.radiometry.curve import CameraResponse
    from hdrio.stack import ExposureStack

DEFAULT_K = 12.5
REFERENCE_CODE_8BIT = 118  # ISO 12232 standard output sensitivity: sRGB 18 % grey

Region = tuple[int, int, int, int]  # x, y, width, height in pixels (top-left origin)


@dataclass(frozen=True)
class Calibration:
    """How to make radiance absolute; recorded in the EXR (``hdrio:calibration``).

    Attributes
    ----------
    method
        ``exif``, ``luminance`` (spot meter) or ``illuminance`` (grey card under lux).
    K
        Reflected-light meter calibration constant, cd s / m^2 (``exif`` only).
    region
        ``(x, y, width, height)`` pixels of the reference surface (reference methods).
    luminance
        The region's luminance in cd/m^2 (``luminance``).
    illuminance, reflectance
        Lux falling on the grey card, and its diffuse reflectance 0..1 (``illuminance``).
    """

    method: str = "exif"
    K: float = DEFAULT_K
    region: Region | None = None
    luminance: float | None = None
    illuminance: float | None = None
    reflectance: float = 0.18

    def __post_init__(self) -> None:
        if self.method not in ("exif", "luminance", "illuminance"):
            raise ValueError(f"unknown calibration method {self.method!r}; use exif, "
                             "luminance or illuminance")
        from hdrio.numbers import check_number

        check_number("--meter-k", self.K, above=0.0,
                     hint="meter constant K must be positive, in cd s/m^2")
        if self.method != "exif" and self.region is None:
            raise ValueError(f"calibration by {self.method} needs a region x,y,w,h")
        if self.method == "luminance":
            check_number("--reference-luminance", self.luminance, above=0.0,
                         hint="calibration by luminance needs a positive cd/m^2 value")
        if self.method == "illuminance":
            check_number("--reference-illuminance", self.illuminance, above=0.0,
                         hint="calibration by illuminance needs a positive lux value")
        check_number("--reference-reflectance", self.reflectance, above=0.0, maximum=1.0,
                     hint="a grey card's diffuse reflectance, in (0, 1]")

    def describe(self) -> str:
        """One line for the EXR header and the summary."""
        if self.method == "exif":
            return (f"exif: L = K N^2 / (t S) at code {REFERENCE_CODE_8BIT}/255, "
                    f"K = {self.K:g}")
        x, y, w, h = self.region  # type: ignore[misc]
        where = f"region {x},{y},{w},{h}"
        if self.method == "luminance":
            return f"luminance: {where} = {self.luminance:g} cd/m^2"
        return (f"illuminance: {where} grey card reflectance {self.reflectance:g} "
                f"under {self.illuminance:g} lx")


def meter_luminance(f_number: float, time_s: float, iso: float, K: float = DEFAULT_K
                    ) -> float:
    """``L_avg = K N^2 / (t S)``: the average scene luminance (cd/m^2) the exposure suits."""
    return K * f_number**2 / (time_s * iso)


def reference_code(code_max: int) -> int:
    """The code of a correctly exposed average scene: 118 of 255, scaled for 16-bit."""
    return int(round(REFERENCE_CODE_8BIT / 255 * code_max))


def exif_scale(stack: ExposureStack, response: CameraResponse, space: str,
               K: float = DEFAULT_K) -> np.ndarray:
    """cd/m^2 per unit of relative luminance, per bracket (they agree for a sound stack).

    Raises :class:`InputError` naming the first bracket without exposure time, f-number
    or ISO in its EXIF.
    """
    if len(stack.metadata) != stack.count:
        raise InputError(stack.files[0], "no EXIF recorded for this stack")
    code = reference_code(stack.code_max)
    codes = np.full((1, response.channels), code, dtype=np.int64)
    linear = response.linearise(codes)
    reference = float(luminance(linear, space)[0]) if linear.shape[-1] == 3 else float(
        linear[0, 0])
    scales = []
    for name, exif, exposure in zip(stack.files, stack.metadata, stack.exposures):
        missing = [key for key in ("ExposureTime", "FNumber", "ISO") if not exif.get(key)]
        if missing:
            raise InputError(name, f"no EXIF {', '.join(missing)}: cannot calibrate absolute "
                                   "luminance from EXIF; give a reference instead")
        L_avg = meter_luminance(float(exif["FNumber"]), float(exif["ExposureTime"]),
                                float(exif["ISO"]), K)
        scales.append(L_avg * float(exposure) / reference)
    return np.asarray(scales)


def region_mean_luminance(radiance: np.ndarray, region: Region, space: str) -> float:
    """Mean luminance of ``radiance`` over ``region`` (same units as ``radiance``)."""
    x, y, w, h = region
    height, width = radiance.shape[:2]
    if w <= 0 or h <= 0 or x < 0 or y < 0 or x + w > width or y + h > height:
        raise HdrioError(f"region {x},{y},{w},{h} is not inside the {width}x{height} image")
    patch = radiance[y: y + h, x: x + w]
    Y = luminance(patch, space) if patch.shape[-1] == 3 else patch[..., 0]
    return float(np.mean(Y))


def absolute_scale(stack: ExposureStack, response: CameraResponse, radiance: np.ndarray,
                   calibration: Calibration, space: str) -> float:
    """The factor that turns ``radiance`` (relative) into cd/m^2 (see module doc)."""
    if calibration.method == "exif":
        scales = exif_scale(stack, response, space, calibration.K)
        spread = scales.max() / scales.min() - 1.0
        if spread > 0.01:
            # EXIF times are rounded to thirds of a stop: more than 1 % means the
            # exposures used in the merge are not those in EXIF (sidecar, explicit).
            raise InputError(stack.files[int(np.argmax(scales))],
                             f"EXIF and the merge's exposures disagree by {100 * spread:.0f} %")
        return float(np.exp(np.mean(np.log(scales))))
    measured = region_mean_luminance(radiance, calibration.region, space)  # type: ignore[arg-type]
    if not measured > 0:
        raise HdrioError("the calibration region has no positive luminance")
    if calibration.method == "luminance":
        target = float(calibration.luminance)  # type: ignore[arg-type]
    else:
        target = calibration.reflectance * float(calibration.illuminance) / math.pi  # type: ignore[arg-type]
    return target / measured
