"""Fitting the noise model (:class:`hdrio.radiometry.noise.NoiseModel`) to a stack.

Fit (:func:`fit_noise`): for pixels seen in two neighbouring brackets, the two estimates
``x_j`` and ``x_{j+1}`` of the same radiance differ by noise alone, so ``var(x_{j+1} -
x_j) = var(x_j) + var(x_{j+1})``, linear in the four terms. Each pair's disagreement is
divided by its predicted standard deviation; the pairs of every bracket pair are pooled
into bins of brightness, and in each bin the robust spread about 0
(:func:`robust_spread`: a constant offset between two brackets, an exposure time's
error, counts as disagreement too) should be 1. The terms are fitted in log space so
that every bin counts alike (a robust Levenberg-Marquardt fit, Cauchy weights), then the
prediction is divided by the measured spread and fitted again, until the two agree:
``benchmarks/noise_model.py`` measures the result per decile of brightness. Pixels
within :data:`CLIP_RADIUS` of a clipped channel are left out (a camera bends the
channels next to a clip; deghosting ignores them too).

A term the data cannot fix takes the floor of the encoding
(:func:`hdrio.radiometry.noise.encoding_floors`), never zero.

Two frames of one exposure (a repeat: a ladder capped by the shutter) are not a pair of
the fit: their estimates share the response's error (the same code reads the same
``f^-1``), and a JPEG's quantisation of one picture, so they disagree by less than the
model says two brackets do. Fitted with them, a 7-frame JPEG ladder of the Desk scene
with one exposure repeated came out with a fifth of the plain ladder's code noise and a
third of its red shot noise.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from hdrio.io.staging import candidate_stride, release, strided_copy
from hdrio.parallel import map_on_threads
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.grouped import group_medians
from hdrio.radiometry.noise import (
    QUANTISATION,
    RELATIVE_FLOOR,
    TERMS,
    NoiseModel,
    away_from_the_ends,
    code_slope,
    encoding_floors,
)
from hdrio.stack import exposure_columns, same_as_before

NOISE_GRID_LIMIT = 2**14
"""Pixels the fit reads: a regular grid of at most this many (as the sampler's grid)."""

CLIP_TOP = 0.98
CLIP_RADIUS = 2
"""Grid pixels with a channel at or above :data:`CLIP_TOP` of ``Z_max`` within this many
pixels, in either bracket of a pair, stay out of the fit (a camera's highlight roll-off,
JPEG's half-resolution chroma next to a clip), and so do those codes themselves."""

_BINS = 20  # pooled bins of brightness, per channel
_MIN_PER_BIN = 24  # a spread from fewer pairs is too rough to fit
_MAX_PAIRS = 16_000  # pairs a channel's fit reads (every k-th beyond)
_ROUNDS = 10  # steps that bring the measured spread to 1 in every bin
_TUNING = 0.3  # ln spread: a bin 35 % off its prediction counts half
_TRIM = 5.0  # robust_spread keeps |u| within this many sigmas
_MAD_TO_SIGMA = 1.4826  # sigma of a normal distribution from its median absolute deviation

def noise_grid(codes: np.ndarray, limit: int = NOISE_GRID_LIMIT) -> np.ndarray:
    """A regular grid of at most ``limit`` pixels of every bracket, ``(P, n, C)``."""
    count, height, width, channels = codes.shape
    grid = strided_copy(codes, grid_stride(height, width, limit))
    return grid.reshape(count, -1, channels)


def grid_stride(height: int, width: int, limit: int = NOISE_GRID_LIMIT) -> int:
    """The stride of :func:`noise_grid` (``codes[:, ::stride, ::stride]``)."""
    return candidate_stride(height, width, limit)


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
    repeat = same_as_before(exposures[:, c])
    for j in range(grid.shape[0] - 1):
        if repeat[j]:
            continue  # a repeat (hdrio.stack.repeated_exposures): see the module docstring
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
    total = np.bincount(groups, magnitude * kept, count)
    return np.sqrt(np.pi / 2) * total / np.maximum(np.bincount(groups, kept, count), 1)


def _fit_channel(pairs, response, c, floors):
    """The four fitted terms of one channel (module docstring), each at least its floor
    (``floors``: ``(4,)``, and ``common``, the JPEG term, for the usable codes), or
    ``None`` when too few bins can be measured."""
    R, difference, brightness, _, zs, zl = pairs
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
        usable = away_from_the_ends(X, np.maximum(
            theta[0] * X + theta[1] + (theta[2] + common[c]) * slope2,
            (RELATIVE_FLOOR * X) ** 2))
        return np.where(usable[zs] & usable[zl], level, _BINS)

    def log_spreads(phi, groups, limits):
        """``ln`` of each bin's measured spread of the disagreement over its prediction
        by ``theta`` (``groups`` and the trim ``limits`` held for a round: an objective
        whose pairs moved with ``theta`` rewarded a model that left bins empty)."""
        scores = difference / np.sqrt(R @ (floor + np.exp(phi) / scale))
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

    def channel_fit(c: int) -> tuple[tuple | None, np.ndarray | None]:
        pairs = _pairs(grid, near, times, X, slope2, c, response.code_max) \
            if count > 1 else None
        return pairs, None if pairs is None else _fit_channel(
            pairs, response, c, np.array([floors[term][c] for term in TERMS]))

    for c, (pairs, theta) in enumerate(map_on_threads(channel_fit, list(range(channels)))):
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
