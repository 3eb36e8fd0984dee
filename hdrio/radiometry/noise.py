"""The noise model: the variance of every linearised observation, fitted from the stack.

An observation is a code ``z`` of bracket ``j`` (exposure ``dt_j``); the response turns it
into the sensor exposure ``X = f^-1(z)`` (relative units: ``X = 1`` at the middle code)
and into a radiance estimate ``x_j = X / dt_j``. Its variance is modelled as

    var(X | z) = shot * X  +  read  +  code * (dX/dz)^2  +  relative * X^2
    var(x_j | z) = var(X | z) / dt_j^2

* ``shot``: photon (shot) noise, Poisson, so proportional to the signal;
* ``read``: the signal-independent floor (read noise, dark current, a film's fog);
* ``code``: noise in code units (uniform quantisation is 1/12 of a code squared; JPEG's
  DCT quantisation adds more), carried into ``X`` through the response's slope;
* ``relative``: disagreement proportional to the signal (film grain in density, a scan's
  or a warp's sub-pixel misregistration, exposure jitter). The first three are the
  sensor's; real stacks disagree by this too (Debevec's Memorial scans by 3-9 % r.m.s.).

This is the model of Granados et al. (2010) and Aguerrebere et al. (2014) (shot + read
noise of the raw signal) with the quantisation term of Mitsunaga & Nayar's analysis,
stated for a camera whose response is only known through ``g = ln f^-1``. It is the one
thing the merge's weights (:mod:`hdrio.radiometry.estimators`), the maximum-likelihood
response (:mod:`hdrio.response.robertson2003`), the uncertainty layer and deghosting read.

The fit, from the stack's own bracket-to-bracket disagreement, is
:mod:`hdrio.radiometry.noise_fit`.

A term the data cannot fix (too small to show anywhere the brackets overlap) is never
zero: it takes the floor of the encoding (:func:`encoding_floors`: the quantisation of
8-bit JPEG, 8-bit, 16-bit or linear codes at black and at white), and the header says
which terms were fitted and which floored (``hdrio:noiseOrigin``). A fitted model with a
zero term is a wrong model: a zero read noise let near-black codes of short brackets
claim almost all the weight, in coloured speckle, on real night stacks.

References
----------
Granados, M., Ajdin, B., Wand, M., Theobalt, C., Seidel, H.-P., & Lensch, H. P. A.
(2010). Optimal HDR reconstruction with linear digital cameras. CVPR 2010, 215-222.

Aguerrebere, C., Delon, J., Gousseau, Y., & Musé, P. (2014). Best algorithms for HDR
image generation. A study of performance bounds. SIAM J. Imaging Sciences 7(1), 1-34.

Mitsunaga, T., & Nayar, S. K. (1999). Radiometric self calibration. CVPR 1999.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hdrio.radiometry.curve import CameraResponse
from hdrio.stack import exposure_columns

TERMS = ("shot", "read", "code", "relative", "common")

QUANTISATION = 1.0 / 12.0
"""Variance of rounding to integer codes (code units squared)."""

JPEG_COMMON_VARIANCE = 36.0
"""JPEG's error in code units squared (6 codes r.m.s.), in every observation of a JPEG
bracket and shared by its neighbours (:attr:`NoiseModel.common`). Quality 90 with 4:2:0
chroma, on the truth harness's textured scenes, errs by 5-10 codes r.m.s. in green and
7-30 in red and blue against the codes it was given, while neighbouring brackets
disagree by about one code (median absolute deviation): the same texture is subsampled
and quantised alike in each. Weighting by it (with the fitted terms) gave the harness's
JPEG group a median error of 3.94 % (4, 9, 16: 4.18, 4.05, 4.00 %; none: 5.34 %;
before, a code term floored at 4 and nothing else: 3.93 %)."""

LOSSY_SUFFIXES = (".jpg", ".jpeg", ".jpe", ".jfif")

ENCODINGS = ("8-bit JPEG", "8-bit", "16-bit", "linear")
"""The encodings whose quantisation floors the terms (:func:`encoding_floors`)."""

RELATIVE_FLOOR = 1e-6
"""The smallest relative standard deviation an observation has."""
_MARGIN_SIGMAS = 2.0  # observations this close to black or saturation (in sigmas) stay out



@dataclass(frozen=True)
class NoiseModel:
    """The noise of an observation per channel (see module docstring).

    Attributes
    ----------
    shot, read, code
        ``(C,)``: ``var(X | z) = shot X + read + code (dX/dz)^2``, the observation's own
        noise, in the response's relative units of ``X`` (``X = 1`` at the middle code)
        and code units for ``code``.
    source
        ``"fitted"`` (from the stack), ``"given"`` or ``"quantisation"`` (nothing could
        be measured: the encoding's floors).
    pairs
        Pixel pairs the fit used (0 unless fitted).
    relative
        ``(C,)``: ``relative X^2`` more that two brackets disagree by, which is no
        observation's own noise (``None``: 0).
    common
        ``(C,)``: ``common (dX/dz)^2`` more error in every observation that neighbouring
        brackets share, so never disagree by (JPEG's; ``None``: 0).
    origin
        ``{term: ("fitted" | "floor" | "encoding", ...)}`` per channel, when fitted.
    """

    shot: np.ndarray
    read: np.ndarray
    code: np.ndarray
    source: str = "given"
    pairs: int = 0
    relative: np.ndarray | None = None
    common: np.ndarray | None = None
    origin: dict[str, tuple[str, ...]] = field(default_factory=dict)

    @classmethod
    def quantisation_only(cls, channels: int) -> NoiseModel:
        """No photon or read noise: integer rounding alone (a clean render, a fallback)."""
        zeros = np.zeros(channels)
        return cls(zeros, zeros.copy(), np.full(channels, QUANTISATION), "quantisation")

    @property
    def channels(self) -> int:
        return int(np.size(self.shot))

    def exposure_variance(self, response: CameraResponse) -> np.ndarray:
        """``var(X | z) = shot X + read + code (dX/dz)^2`` at every code, ``(levels, C)``
        (relative exposure squared): the observation's own noise, which clipping at black
        or saturation cuts off (the margins of :func:`usable_codes`)."""
        X = np.exp(response.log_inverse)
        variance = self.shot * X + self.read + self.code * code_slope(response) ** 2
        # A flat stretch of the response (slope 0) with no photon or read noise would
        # claim an exact observation: floor at a relative deviation of 1e-6.
        return np.maximum(variance, (RELATIVE_FLOOR * X) ** 2)

    def attributes(self) -> dict[str, object]:
        """The EXR header's record of the model (``hdrio:noise*``)."""
        def text(values):
            return ",".join(f"{v:.4g}" for v in np.atleast_1d(
                np.zeros(self.channels) if values is None else values))
        out = {"hdrio:noiseModel": "var(X) = shot*X + read + code*(dX/dz)^2 "
                                   "(+ common*(dX/dz)^2 in weights, + relative*X^2 between "
                                   "brackets)",
               "hdrio:noiseShot": text(self.shot), "hdrio:noiseRead": text(self.read),
               "hdrio:noiseCode": text(self.code), "hdrio:noiseRelative": text(self.relative),
               "hdrio:noiseCommon": text(self.common), "hdrio:noiseSource": self.source}
        if self.origin:
            out["hdrio:noiseOrigin"] = "; ".join(f"{term} {','.join(self.origin[term])}"
                                                 for term in TERMS if term in self.origin)
        return out


def code_slope(response: CameraResponse) -> np.ndarray:
    """``dX/dz`` at every code, ``(levels, C)``: central differences of ``f^-1``."""
    X = np.exp(response.log_inverse)
    if X.shape[0] < 2:
        return np.zeros_like(X)
    return np.gradient(X, axis=0)


def observation_variance(response: CameraResponse, exposures, noise: NoiseModel, *,
                         disagreement: bool = False) -> np.ndarray:
    """``var(x_j | z)`` of every bracket's radiance estimate, ``(P, C, levels)``.

    Units: relative radiance squared (``x_j = f^-1(z) / dt_j``). By default the error
    that averaging brackets reduces, what inverse-variance weights read: the
    observation's own noise (:meth:`NoiseModel.exposure_variance`) and JPEG's error
    (``common``). With ``disagreement``, what two brackets' estimates differ by, what a
    consistency test reads (deghosting, clipping): the observation's own noise and the
    ``relative`` term, ``var(x_j - x_k) = var_j + var_k``.
    """
    variance = noise.exposure_variance(response)
    extra = noise.relative if disagreement else noise.common
    if extra is not None:
        factor = np.exp(response.log_inverse) if disagreement else code_slope(response)
        variance = variance + extra * factor**2
    return variance.T[None] / exposure_columns(exposures)[:, :, None] ** 2


def usable_codes(response: CameraResponse, noise: NoiseModel) -> np.ndarray:
    """``(levels, C)`` booleans: codes safely away from black and from saturation.

    An observation within :data:`_MARGIN_SIGMAS` standard deviations (of its own noise,
    :meth:`NoiseModel.exposure_variance`) of the black level ``f^-1(0)`` or of the
    saturation level ``f^-1(Z_max)`` is biased: the noise that would have taken it past
    the end was cut off there. Codes 0 and ``Z_max`` themselves are never usable.
    """
    variance = noise.exposure_variance(response)
    if noise.common is not None:  # JPEG's error: its near-black codes are unusable too
        variance = variance + noise.common * code_slope(response) ** 2
    return away_from_the_ends(np.exp(response.log_inverse), variance)


def away_from_the_ends(X: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """:func:`usable_codes` from ``X = f^-1(z)`` and its variance (``(levels, ...)``)."""
    sigma = np.sqrt(variance)
    usable = (X - X[0] > _MARGIN_SIGMAS * sigma) & (X[-1] - X > _MARGIN_SIGMAS * sigma)
    usable[0] = usable[-1] = False
    return usable


def supported_range(response: CameraResponse) -> np.ndarray:
    """``(levels, C)``: codes from the first to the last the solve supported, per channel.

    Codes inside that range that no sample fell on (most of them at 16 bits, where the
    solve sees 1024 levels) have ``g`` interpolated between supported neighbours: as good
    as their neighbours, so they keep their weight.
    """
    supported = np.asarray(response.supported, dtype=bool)
    after_first = np.logical_or.accumulate(supported, axis=0)
    before_last = np.logical_or.accumulate(supported[::-1], axis=0)[::-1]
    return after_first & before_last


def noise_encoding(files, code_max: int, linear: bool = False) -> str:
    """Which of :data:`ENCODINGS` the brackets are: ``linear`` for camera RAW (or
    ``linear``), else by the files' suffix and the codes' depth."""
    if linear:
        return "linear"
    if any(str(name).lower().endswith(LOSSY_SUFFIXES) for name in files or ()):
        return "8-bit JPEG"
    return "8-bit" if code_max <= 255 else "16-bit"


def encoding_floors(response: CameraResponse, encoding: str,
                    code_floor: float = QUANTISATION) -> dict[str, np.ndarray]:
    """The least each term can be, ``{term: (C,)}``, from the encoding's quantisation.

    The code term: the rounding of integer codes (``code_floor``, 1/12). An encoding
    puts its codes where a camera's noise can use them: 8-bit files on sRGB's curve (a
    linear step of 1 / (255 * 12.92) of white at black, a slope of 2.4 / (255 * 1.055)
    of white at white), 16-bit and linear files a step of 1 / Z_max throughout. A noise
    below the rounding of those steps would be lost in it: the read term is at least the
    rounding's variance at black, the shot term at least its variance at white (``X_w =
    f^-1(Z_max)``, per channel). The relative term's floor is 0 (no bracket pair need
    disagree by more than its noise); the common term is :data:`JPEG_COMMON_VARIANCE` for
    JPEG, else 0 (not fitted: neighbouring brackets cannot show it)."""
    white = np.exp(np.asarray(response.log_inverse, np.float64)[-1])
    if encoding in ("8-bit JPEG", "8-bit"):
        black, slope = 1.0 / (255 * 12.92), 2.4 / (255 * 1.055)
    else:
        black = slope = 1.0 / response.code_max
    common = JPEG_COMMON_VARIANCE if encoding == "8-bit JPEG" else 0.0
    return {"shot": QUANTISATION * (white * slope) ** 2 / white,
            "read": QUANTISATION * (white * black) ** 2,
            "code": np.full(white.shape, code_floor), "relative": np.zeros(white.shape),
            "common": np.full(white.shape, common)}


