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

Fit (:func:`fit_noise`): for pixels seen in two neighbouring brackets, the two estimates
``x_j`` and ``x_{j+1}`` of the same radiance differ by noise alone, so ``var(x_{j+1} -
x_j) = var(x_j) + var(x_{j+1})``, linear in the four terms. Each pair's disagreement is
divided by its predicted standard deviation; the pairs of every bracket pair are pooled
into bins of brightness, and in each bin the robust spread (the median absolute
deviation, about each bracket pair's median: an exposure time's error is not noise)
should be 1. The terms are fitted in log space so that every bin counts alike (a robust
Levenberg-Marquardt fit, Cauchy weights), then the prediction is divided by the measured
spread and fitted again, until the two agree: ``benchmarks/noise_model.py`` measures the
result per decile of brightness. Pixels within :data:`CLIP_RADIUS` of a clipped channel
are left out (a camera bends the channels next to a clip; deghosting ignores them too).

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
from numba import njit

from hdrio.io.staging import candidate_stride, release, strided_copy
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.grouped import group_medians
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

NOISE_GRID_LIMIT = 2**14
"""Pixels the fit reads: a regular grid of at most this many (as the sampler's grid)."""

CLIP_TOP = 0.98
CLIP_RADIUS = 2
"""Grid pixels with a channel at or above :data:`CLIP_TOP` of ``Z_max`` within this many
pixels, in either bracket of a pair, stay out of the fit (a camera's highlight roll-off,
JPEG's half-resolution chroma next to a clip), and so do those codes themselves."""

_BINS = 20  # pooled bins of brightness, per channel
_PAIR_BINS = 16  # bins per bracket pair for the starting fit
_MIN_PER_BIN = 24  # a spread from fewer pairs is too rough to fit
_MAX_PAIRS = 16_000  # pairs a channel's fit reads (every k-th beyond)
_ROUNDS = 10  # steps that bring the measured spread to 1 in every bin
_TUNING = 0.3  # ln spread: a bin 35 % off its prediction counts half
_TRIM = 5.0  # robust_spread keeps |u| within this many sigmas
_MAD_TO_SIGMA = 1.4826  # sigma of a normal distribution from its median absolute deviation
_RELATIVE_FLOOR = 1e-6  # the smallest relative standard deviation an observation has
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
        return np.maximum(variance, (_RELATIVE_FLOOR * X) ** 2)

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
    return _away_from_the_ends(np.exp(response.log_inverse), variance)


def _away_from_the_ends(X: np.ndarray, variance: np.ndarray) -> np.ndarray:
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


def noise_grid(codes: np.ndarray, limit: int = NOISE_GRID_LIMIT) -> np.ndarray:
    """A regular grid of at most ``limit`` pixels of every bracket, ``(P, n, C)``."""
    count, height, width, channels = codes.shape
    grid = strided_copy(codes, grid_stride(height, width, limit))
    return grid.reshape(count, -1, channels)


def grid_stride(height: int, width: int, limit: int = NOISE_GRID_LIMIT) -> int:
    """The stride of :func:`noise_grid` (``codes[:, ::stride, ::stride]``)."""
    return candidate_stride(height, width, limit)


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


@njit(cache=True, nogil=True)
def _clipped_near(codes, stride, radius, top, out):  # pragma: no cover - compiled
    """``out[i, k]``: some channel of ``codes`` ``(H, W, C)`` at or above ``top`` within
    ``radius`` of grid pixel ``(i * stride, k * stride)``."""
    height, width, channels = codes.shape
    for i in range(out.shape[0]):
        y = i * stride
        for k in range(out.shape[1]):
            x = k * stride
            found = False
            for yy in range(max(0, y - radius), min(height, y + radius + 1)):
                for xx in range(max(0, x - radius), min(width, x + radius + 1)):
                    for c in range(channels):
                        found |= codes[yy, xx, c] >= top
            out[i, k] = found


def near_clipping(codes: np.ndarray, stride: int, top: int) -> np.ndarray:
    """``(P, n)``: grid pixels (``codes[:, ::stride, ::stride]``) within
    :data:`CLIP_RADIUS` of a channel at or above ``top``."""
    count, height, width, _ = codes.shape
    shape = (-(-height // stride), -(-width // stride))
    out = np.empty((count, *shape), np.bool_)
    for j in range(count):
        _clipped_near(codes[j], stride, CLIP_RADIUS, top, out[j])
        release(codes, j)
    return out.reshape(count, -1)


def _pairs(grid, near, exposures, X, slope2, c, code_max):
    """Every neighbouring bracket pair's pixels on the grid, usable in both (not black,
    below the top codes, not near a clip): ``(regressors (n, 4), difference, brightness,
    pair index, shorter code, longer code)``; ``near`` ``(P, n)`` or ``None``."""
    out = [[] for _ in range(6)]
    for j in range(grid.shape[0] - 1):
        zs, zl = grid[j, :, c].astype(np.intp), grid[j + 1, :, c].astype(np.intp)
        ok = (zs > 0) & (zl > 0) & (zs < CLIP_TOP * code_max) & (zl < CLIP_TOP * code_max)
        if near is not None:
            ok &= ~near[j] & ~near[j + 1]
        zs, zl = zs[ok], zl[ok]
        ts, tl = exposures[j, c], exposures[j + 1, c]
        xs, xl = X[zs, c] / ts, X[zl, c] / tl
        out[0].append(np.column_stack([xs / ts + xl / tl, np.full(zs.size, ts**-2 + tl**-2),
                                       slope2[zs, c] / ts**2 + slope2[zl, c] / tl**2,
                                       xs**2 + xl**2]))
        for k, value in enumerate((xl - xs, 0.5 * (xs + xl), np.full(zs.size, j), zs, zl)):
            out[k + 1].append(value)
    if not out[1]:
        return None
    joined = [np.concatenate(part) for part in out]
    step = max(1, joined[1].size // _MAX_PAIRS)
    return [part[::step] for part in joined]


def trim_limits(scores: np.ndarray, groups: np.ndarray, count: int) -> np.ndarray:
    """``(count,)``: the limits :func:`robust_spread` keeps each group's scores within:
    :data:`_TRIM` times its standard deviation from its median absolute value."""
    return _TRIM * np.nan_to_num(_MAD_TO_SIGMA * group_medians(np.abs(scores), groups, count))


def robust_spread(scores: np.ndarray, groups: np.ndarray, count: int,
                  limits: np.ndarray | None = None) -> np.ndarray:
    """The standard deviation about 0 of each group of ``scores``, ``(count,)``, robustly:
    ``sqrt(pi / 2)`` times the mean absolute value of those within each group's
    ``limits`` (:func:`trim_limits`, by default): a moving object's disagreements are
    left out. Codes are integers, and the median of a difference of codes jumps between
    them (20 % high on the demo's shot noise); the mean of its absolute value does not."""
    magnitude = np.abs(scores)
    limits = trim_limits(scores, groups, count) if limits is None else limits
    kept = magnitude <= limits[groups]
    if __import__("os").environ.get("HDRIO_MAD") == "1":
        return _MAD_TO_SIGMA * np.nan_to_num(group_medians(magnitude, groups, count))
    total = np.bincount(groups, magnitude * kept, count)
    return np.sqrt(np.pi / 2) * total / np.maximum(np.bincount(groups, kept, count), 1)


def _fit_channel(pairs, response, c, floors):
    """The four fitted terms of one channel (module docstring), each at least its floor
    (``floors``: ``(4,)``, and ``common``, the JPEG term, for the usable codes), or
    ``None`` when too few bins can be measured."""
    R, difference, brightness, pair, zs, zl = pairs
    floor, common = floors[:4], np.full(response.channels, floors[4])  # (C,): as a model's
    if difference.size < 3 * _MIN_PER_BIN:
        return None
    edges = np.quantile(brightness, np.linspace(0.0, 1.0, _BINS + 1))
    level = np.clip(np.searchsorted(edges, brightness, side="right") - 1, 0, _BINS - 1)
    sizes = np.bincount(level, minlength=_BINS).astype(np.float64)
    A = np.column_stack([np.bincount(level, R[:, k], _BINS) for k in range(4)]) \
        / np.maximum(sizes, 1)[:, None]
    # Start: each bin's spread of the differences themselves against its regressors'
    # means: the least squares of the relative residuals (NNLS).
    y = robust_spread(difference, level, _BINS) ** 2
    good = (sizes >= _MIN_PER_BIN) & (y > 0) & np.all(np.isfinite(A), axis=1)
    if np.count_nonzero(good) < 3:
        return None
    scaled = A[good] / y[good, None]
    column = np.maximum(scaled.max(axis=0), 1e-300)
    start = nonnegative_least_squares(scaled / column, np.ones(int(good.sum()))) / column
    scale = np.maximum(np.median(A[good], axis=0), 1e-300)  # terms of order 1 inside
    X = np.exp(response.log_inverse[:, c])
    slope2 = code_slope(response)[:, c] ** 2

    def groups_at(phi):
        """Each pair's bin, or one more bin for the pairs left out: the codes the merge
        would use under ``theta = floor + exp(phi) / scale`` (:func:`usable_codes`)."""
        theta = floor + np.exp(phi) / scale
        usable = _away_from_the_ends(X, np.maximum(
            theta[0] * X + theta[1] + (theta[2] + common[c]) * slope2,
            (_RELATIVE_FLOOR * X) ** 2))
        return np.where(usable[zs] & usable[zl], level, _BINS)

    def log_spreads(phi, groups, limits):
        """``ln`` of each bin's measured spread of the disagreement over its prediction
        by ``theta`` (``groups`` and the trim ``limits`` held for a round: an objective
        whose pairs moved with ``theta`` rewarded a model that left bins empty)."""
        scores = difference / np.sqrt(R @ (floor + np.exp(phi) / scale))
        if __import__("os").environ.get("HDRIO_CENTRE") == "1":
            key = groups * 64 + pair
            scores = scores - np.nan_to_num(group_medians(scores, key, (_BINS + 1) * 64))[key]
        with np.errstate(divide="ignore"):
            return np.log(robust_spread(scores, groups, _BINS + 1, limits)[:_BINS])

    phi = np.log(np.maximum(start - floor, 1e-6 / scale) * scale)
    damping = 1e-2
    for _ in range(_ROUNDS):
        # Levenberg-Marquardt on the bins' ln spread (derivatives by differences),
        # Cauchy-weighted: a bin where clipping truncates the noise cannot be fitted.
        groups = groups_at(phi)
        sizes = np.bincount(groups, minlength=_BINS + 1)[:_BINS]
        limits = trim_limits(difference / np.sqrt(R @ (floor + np.exp(phi) / scale)),
                             groups, _BINS + 1)
        r = log_spreads(phi, groups, limits)
        bins = (sizes >= _MIN_PER_BIN) & np.isfinite(r)
        if np.count_nonzero(bins) < 3:
            return None
        weight = np.sqrt(np.minimum(sizes, 200.0))[bins]

        def loss(r, weight=weight, bins=bins):
            return float(np.sum(weight * np.log1p((r[bins] / _TUNING) ** 2)))

        current = loss(r)
        J = np.empty((int(bins.sum()), phi.size))
        for k in range(phi.size):
            shifted = phi.copy()
            shifted[k] += 0.1
            with np.errstate(invalid="ignore"):  # a bin emptied by the step: no slope
                J[:, k] = (log_spreads(shifted, groups, limits) - r)[bins] / 0.1
        J[~np.isfinite(J)] = 0.0
        w = weight / (1.0 + (r[bins] / _TUNING) ** 2)
        H = (J * w[:, None]).T @ J
        gradient = (J * w[:, None]).T @ r[bins]
        improved = False
        while damping < 1e6:
            step = np.linalg.solve(H + damping * np.diag(np.diag(H) + 1e-9), -gradient)
            trial = np.clip(phi + np.clip(step, -3.0, 3.0), -60.0, 60.0)
            r_trial = log_spreads(trial, groups, limits)
            if np.all(np.isfinite(r_trial[bins])) and loss(r_trial) < current:
                improved = current - loss(r_trial) > 1e-3 * current
                phi, damping = trial, damping / 3
                break
            damping *= 10.0
        if not improved:
            break
    return floor + np.exp(phi) / scale


def fit_noise(codes: np.ndarray, exposures, response: CameraResponse,
              grid: np.ndarray | None = None, code_floor: float = QUANTISATION, *,
              encoding: str | None = None, exclude: np.ndarray | None = None
              ) -> NoiseModel:
    """Fit the :class:`NoiseModel` from bracket-to-bracket disagreement (module docstring).

    ``codes`` ``(P, H, W, C)`` sorted by exposure; ``exposures`` ``(P,)`` or ``(P, C)``;
    ``grid`` (``(P, n, C)``, from :func:`noise_grid`) when already read; ``code_floor``
    the code term's least value (the rounding of integer codes); ``encoding`` one of
    :data:`ENCODINGS` (:func:`noise_encoding`; by default 8-bit, or 16-bit codes), whose
    quantisation floors the other terms and sets JPEG's common term
    (:func:`encoding_floors`); ``exclude``: ``(P, H, W)`` or ``(H, W)`` observations kept
    out of the merge (``--mask``, ``--exclude-color``), kept out of the fit too (a masked
    block of garbage made a fit's shot noise 20x). Falls back to the floors, per channel,
    when too few bins of pairs can be measured (two brackets of a flat scene, say).
    """
    count, height, width, channels = codes.shape
    encoding = encoding or ("8-bit" if response.code_max <= 255 else "16-bit")
    floors = encoding_floors(response, encoding, code_floor)
    stride = grid_stride(height, width)
    grid = noise_grid(codes) if grid is None else grid
    near, shape = None, (-(-height // stride), -(-width // stride))
    if grid.shape[1] == shape[0] * shape[1]:  # the default grid
        near = near_clipping(codes, stride, int(np.ceil(CLIP_TOP * response.code_max)))
        if exclude is not None:
            held = np.broadcast_to(exclude, (count, height, width))[:, ::stride, ::stride]
            near |= held.reshape(count, -1)
    times = np.broadcast_to(exposure_columns(np.asarray(exposures, np.float64)),
                            (count, channels))
    X = np.exp(np.asarray(response.log_inverse, np.float64))
    slope2 = code_slope(response) ** 2
    fitted = np.zeros((len(TERMS), channels))
    used, seen = 0, np.zeros(channels, bool)
    for c in range(channels):
        pairs = _pairs(grid, near, times, X, slope2, c, response.code_max) \
            if count > 1 else None
        theta = None if pairs is None else _fit_channel(
            pairs, response, c, np.array([floors[term][c] for term in TERMS]))
        if theta is not None:
            fitted[:4, c], seen[c] = theta, True
            used += pairs[1].size
    terms, origin = {}, {}
    for k, term in enumerate(TERMS):
        terms[term] = np.maximum(fitted[k], floors[term])
        # A term within 1 % of its floor (0.01 % of the relative term's deviation):
        # the data did not need it.
        origin[term] = tuple(
            "encoding" if term == "common" else
            "fitted" if seen[c] and fitted[k, c] > 1.01 * floors[term][c] + (
                1e-8 if term == "relative" else 0.0) else "floor" for c in range(channels))
    return NoiseModel(terms["shot"], terms["read"], terms["code"],
                      "fitted" if seen.any() else "quantisation", used, terms["relative"],
                      terms["common"] if terms["common"].any() else None, origin)


def nonnegative_least_squares(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``argmin ||A x - b||`` subject to ``x >= 0``, for a few columns (the noise model's
    four): the best of the unconstrained least-squares solutions on every subset of
    columns that come out non-negative (the optimum is one of them: on its support it
    solves the least squares there). Exact, like ``scipy.optimize.nnls``, without the
    0.2-0.4 s of importing scipy.optimize on every merge."""
    columns = A.shape[1]
    best, best_residual = np.zeros(columns), float(np.dot(b, b))
    for subset in range(1, 1 << columns):
        chosen = [k for k in range(columns) if subset >> k & 1]
        x, *_ = np.linalg.lstsq(A[:, chosen], b, rcond=None)
        if np.all(x >= 0):
            residual = float(np.sum((A[:, chosen] @ x - b) ** 2))
            if residual < best_residual:
                best, best_residual = np.zeros(columns), residual
                best[chosen] = x
    return best
