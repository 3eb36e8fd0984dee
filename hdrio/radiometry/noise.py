"""The noise model: the variance of every linearised observation, fitted from the stack.

An observation is a code ``z`` of bracket ``j`` (exposure ``dt_j``); the response turns it
into the sensor exposure ``X = f^-1(z)`` (relative units: ``X = 1`` at the middle code)
and into a radiance estimate ``x_j = X / dt_j``. Its variance is modelled as

    var(X | z) = shot * X  +  read  +  code * (dX/dz)^2
    var(x_j | z) = var(X | z) / dt_j^2

* ``shot``: photon (shot) noise, Poisson, so proportional to the signal;
* ``read``: the signal-independent floor (read noise, dark current);
* ``code``: noise in code units (uniform quantisation is 1/12 of a code squared; JPEG's
  DCT quantisation adds more), carried into ``X`` through the response's slope.

This is the model of Granados et al. (2010) and Aguerrebere et al. (2014) (shot + read
noise of the raw signal) with the quantisation term of Mitsunaga & Nayar's analysis,
stated for a camera whose response is only known through ``g = ln f^-1``. It is the one
thing the merge's weights (:mod:`hdrio.radiometry.estimators`), the maximum-likelihood
response (:mod:`hdrio.response.robertson2003`), the uncertainty layer and deghosting read.

Fit (:func:`fit_noise`): for pixels seen unclipped in two neighbouring brackets, the two
estimates ``x_j`` and ``x_k`` of the same radiance differ by noise alone, so
``var(x_k - x_j) = var(x_j) + var(x_k)`` is linear in the three parameters. The pairs are
binned by bracket pair and by the shorter bracket's code; each bin's variance is measured
robustly (the median absolute deviation about the bin's median, which also takes out any
bias of the response at those codes), and the parameters are the non-negative
least-squares fit of the binned variances, each bin weighted by its count over its
variance (the relative accuracy of a variance measured from ``n`` values). ``code`` is
kept at least 1/12, the quantisation of integer codes. Per channel, since each channel's
``X`` has its own unit.

References
----------
Granados, M., Ajdin, B., Wand, M., Theobalt, C., Seidel, H.-P., & Lensch, H. P. A.
(2010). Optimal HDR reconstruction with linear digital cameras. CVPR 2010, 215-222.

Aguerrebere, C., Delon, J., Gousseau, Y., & Musé, P. (2014). Best algorithms for HDR
image generation. A study of performance bounds. SIAM J. Imaging Sciences 7(1), 1-34.

Mitsunaga, T., & Nayar, S. K. (1999). Radiometric self calibration. CVPR 1999.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hdrio.io.staging import candidate_stride, strided_copy
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.grouped import group_edges, group_means, group_medians
from hdrio.stack import exposure_columns


def nonnegative_least_squares(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``argmin ||A x - b||`` subject to ``x >= 0``, for a few columns (the noise model's
    three): the best of the unconstrained least-squares solutions on every subset of
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


QUANTISATION = 1.0 / 12.0
"""Variance of rounding to integer codes (code units squared)."""

JPEG_CODE_VARIANCE = 4.0
"""The least code-domain variance of a JPEG's codes (code units squared: 2 codes r.m.s.).

JPEG's error is not noise-like: most codes come back exact and edges, fine texture and
subsampled chroma come back several codes off. The median-based fit sees the first and
misses the second, so for JPEG brackets the code term is floored here. On the truth
harness's six JPEG stacks (quality 90, 4:2:0) the inverse-variance merge's mean median
error is 6.80 % with the fitted term, 6.14 % with this floor (6.21 % for the tutorial's
log-domain merge), and its mean p99 122 % against 138 % for the log merge.
"""

LOSSY_SUFFIXES = (".jpg", ".jpeg", ".jpe", ".jfif")

NOISE_GRID_LIMIT = 2**14
"""Pixels the fit reads: a regular grid of at most this many (as the sampler's grid)."""

_BINS = 24  # bins of the shorter bracket's code, per bracket pair
_MIN_PER_BIN = 24  # a variance from fewer pairs is too rough to fit
_MAD_TO_SIGMA = 1.4826  # sigma of a normal distribution from its median absolute deviation
_RELATIVE_FLOOR = 1e-6  # the smallest relative standard deviation an observation has
_MARGIN_SIGMAS = 2.0  # observations this close to black or saturation (in sigmas) stay out


@dataclass(frozen=True)
class NoiseModel:
    """``var(X | z) = shot X + read + code (dX/dz)^2`` per channel (see module docstring).

    Attributes
    ----------
    shot, read, code
        ``(C,)`` parameters, in the response's relative units of ``X`` (``X = 1`` at
        the middle code) and code units for ``code``.
    source
        ``"fitted"`` (from the stack), ``"given"`` or ``"quantisation"`` (nothing else
        could be measured: codes' rounding only).
    pairs
        Pixel pairs the fit used (0 unless fitted).
    """

    shot: np.ndarray
    read: np.ndarray
    code: np.ndarray
    source: str = "given"
    pairs: int = 0

    @classmethod
    def quantisation_only(cls, channels: int) -> NoiseModel:
        """No photon or read noise: integer rounding alone (a clean render, a fallback)."""
        zeros = np.zeros(channels)
        return cls(zeros, zeros.copy(), np.full(channels, QUANTISATION), "quantisation")

    @property
    def channels(self) -> int:
        return int(np.size(self.shot))

    def exposure_variance(self, response: CameraResponse) -> np.ndarray:
        """``var(X | z)`` at every code, ``(levels, C)`` (relative exposure squared)."""
        X = np.exp(response.log_inverse)
        slope = code_slope(response)
        variance = self.shot * X + self.read + self.code * slope**2
        # A flat stretch of the response (slope 0) with no photon or read noise would
        # claim an exact observation: floor at a relative deviation of 1e-6.
        return np.maximum(variance, (_RELATIVE_FLOOR * X) ** 2)

    def attributes(self) -> dict[str, object]:
        """The EXR header's record of the model (``hdrio:noise*``)."""
        def text(values):
            return ",".join(f"{v:.4g}" for v in np.atleast_1d(values))
        return {"hdrio:noiseModel": "var(X) = shot*X + read + code*(dX/dz)^2",
                "hdrio:noiseShot": text(self.shot), "hdrio:noiseRead": text(self.read),
                "hdrio:noiseCode": text(self.code), "hdrio:noiseSource": self.source}


def code_slope(response: CameraResponse) -> np.ndarray:
    """``dX/dz`` at every code, ``(levels, C)``: central differences of ``f^-1``."""
    X = np.exp(response.log_inverse)
    if X.shape[0] < 2:
        return np.zeros_like(X)
    return np.gradient(X, axis=0)


def observation_variance(response: CameraResponse, exposures, noise: NoiseModel
                         ) -> np.ndarray:
    """``var(x_j | z)`` of every bracket's radiance estimate, ``(P, C, levels)``.

    Units: relative radiance squared (``x_j = f^-1(z) / dt_j``).
    """
    per_code = noise.exposure_variance(response).T  # (C, levels)
    return per_code[None] / exposure_columns(exposures)[:, :, None] ** 2


def usable_codes(response: CameraResponse, noise: NoiseModel) -> np.ndarray:
    """``(levels, C)`` booleans: codes safely away from black and from saturation.

    An observation within :data:`_MARGIN_SIGMAS` standard deviations (of its own noise)
    of the black level ``f^-1(0)`` or of the saturation level ``f^-1(Z_max)`` is biased:
    the noise that would have taken it past the end was cut off there. Codes 0 and
    ``Z_max`` themselves are never usable.
    """
    X = np.exp(response.log_inverse)
    sigma = np.sqrt(noise.exposure_variance(response))
    usable = (X - X[0] > _MARGIN_SIGMAS * sigma) & (X[-1] - X > _MARGIN_SIGMAS * sigma)
    usable[0] = usable[-1] = False
    return usable


def noise_grid(codes: np.ndarray, limit: int = NOISE_GRID_LIMIT) -> np.ndarray:
    """A regular grid of at most ``limit`` pixels of every bracket, ``(P, n, C)``."""
    count, height, width, channels = codes.shape
    grid = strided_copy(codes, candidate_stride(height, width, limit))
    return grid.reshape(count, -1, channels)


def code_variance_floor(files) -> float:
    """:data:`JPEG_CODE_VARIANCE` when any bracket is a JPEG file, else :data:`QUANTISATION`."""
    lossy = any(str(name).lower().endswith(LOSSY_SUFFIXES) for name in files)
    return JPEG_CODE_VARIANCE if lossy else QUANTISATION


def fit_noise(codes: np.ndarray, exposures, response: CameraResponse,
              grid: np.ndarray | None = None, code_floor: float = QUANTISATION
              ) -> NoiseModel:
    """Fit the :class:`NoiseModel` from bracket-to-bracket disagreement (module docstring).

    ``codes`` ``(P, H, W, C)`` sorted by exposure; ``grid`` (``(P, n, C)``, from
    :func:`noise_grid`) when already read; ``code_floor``: the least code-domain variance
    (:func:`code_variance_floor`). Falls back to that alone, per channel, when fewer
    than three bins of pairs can be measured (two brackets of a flat scene, say).
    """
    exposures = np.asarray(exposures, dtype=np.float64)
    grid = noise_grid(codes) if grid is None else grid
    code_max = response.code_max
    X = np.exp(response.log_inverse)
    slope2 = code_slope(response) ** 2
    channels = grid.shape[2]
    shot, read, code = np.zeros(channels), np.zeros(channels), np.full(channels, code_floor)
    used = 0
    fitted = np.zeros(channels, dtype=bool)
    for c in range(channels):
        rows, targets, counts = [], [], []
        for j in range(grid.shape[0] - 1):
            z_short, z_long = grid[j, :, c], grid[j + 1, :, c]
            ok = (z_short > 0) & (z_short < code_max) & (z_long > 0) & (z_long < code_max)
            if np.count_nonzero(ok) < _MIN_PER_BIN:
                continue
            zs, zl = z_short[ok].astype(np.intp), z_long[ok].astype(np.intp)
            ts, tl = exposures[j], exposures[j + 1]
            xs, xl = X[zs, c] / ts, X[zl, c] / tl
            difference = xl - xs
            radiance = 0.5 * (xs + xl)
            bins = np.minimum(zs * _BINS // (code_max + 1), _BINS - 1)
            # Every bin's robust spread and means at once (hdrio.radiometry.grouped).
            centre = group_medians(difference, bins, _BINS)
            spread = _MAD_TO_SIGMA * group_medians(np.abs(difference - centre[bins]), bins,
                                                   _BINS)
            order, edges = group_edges(bins, _BINS)
            sizes = np.diff(edges)
            counted = (sizes >= _MIN_PER_BIN) & (spread > 0)
            if not counted.any():
                continue
            mean_e = group_means(radiance, order, edges)[counted]
            slope_short = group_means(slope2[zs, c], order, edges)[counted]
            slope_long = group_means(slope2[zl, c], order, edges)[counted]
            rows += np.column_stack([mean_e * (1 / ts + 1 / tl),
                                     np.full(mean_e.size, 1 / ts**2 + 1 / tl**2),
                                     slope_short / ts**2 + slope_long / tl**2]).tolist()
            targets += (spread[counted] ** 2).tolist()
            counts += sizes[counted].tolist()
        if len(rows) < 3:
            continue
        A, y, n = np.asarray(rows), np.asarray(targets), np.asarray(counts, np.float64)
        finite = np.all(np.isfinite(A), axis=1) & np.isfinite(y)
        A, y, n = A[finite], y[finite], n[finite]
        if y.size < 3:
            continue
        y_noise = y - code_floor * A[:, 2]  # integer rounding is there regardless
        scale = np.sqrt(n) / y  # each bin to relative accuracy
        column = np.maximum(np.abs(A * scale[:, None]).max(axis=0), 1e-300)
        solution = nonnegative_least_squares(A * scale[:, None] / column, y_noise * scale)
        shot[c], read[c], extra = solution / column
        code[c] += extra
        used += int(n.sum())
        fitted[c] = True
    if not fitted.any():
        return NoiseModel(shot, read, code, "quantisation")
    return NoiseModel(np.maximum(shot, 0.0), np.maximum(read, 0.0), code, "fitted", used)
