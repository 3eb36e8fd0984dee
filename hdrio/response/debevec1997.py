"""Debevec & Malik (1997) camera response recovery, as a sparse least-squares problem.

The objective is the tutorial's ``gsolve.m`` exactly. Unknowns are ``g(z)`` for every code
level ``z`` (``n`` of them) and ``ln E_i`` for every sample ``i`` (``N`` of them); rows are

* data, one per sample ``i`` and bracket ``j``:  ``w(Z_ij) (g(Z_ij) - ln E_i) = w(Z_ij) ln dt_j``
* the gauge ``g(z_mid) = 0`` (``z_mid = n // 2``, code 128 for 8-bit)
* smoothness for ``z = 1 .. n-2``:  ``lambda w(z) (g(z-1) - 2 g(z) + g(z+1)) = 0``

The matrix ``A`` ((N P + n - 1) x (n + N)) is defined, sparse, by
:func:`debevec1997_system`, the reference the tests solve densely; the solve itself never
builds it (:mod:`hdrio.response.normal_equations`). We solve the normal equations by
eliminating the ``ln E`` block, whose normal matrix is diagonal: the Schur complement is
an ``n x n`` matrix accumulated straight from the samples' code pairs, so the work is
``O(N P^2 + n^3)`` whatever the sample count, and up to two steps of iterative refinement
against the exact residual bring the result to the accuracy of a dense least-squares
solve. Normal equations square the condition number, so when the reduced matrix is
ill-conditioned (a huge ``lambda``, say) we solve the same reduced problem by SVD
instead: the ``ln E`` unknowns are projected out of each sample's rows, leaving a dense
``(N P + n - 1) x n`` least-squares problem whose singular values also tell a genuinely
undetermined response from a merely stiff one.

Unknowns that no equation touches (codes whose weight is zero and that no active
smoothness row reaches, samples with zero weight in every bracket) take the value 0, as
the minimum-norm solution of ``numpy.linalg.lstsq`` (and MATLAB's ``pinv``) would.

References
----------
Debevec, P. E., & Malik, J. (1997). Recovering high dynamic range radiance maps from
photographs. SIGGRAPH 97, 369-378. doi:10.1145/258734.258884
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from hdrio.errors import ResponseSolveError
from hdrio.radiometry.curve import (
    CameraResponse,
    fill_unsupported,
    log_fit,
    monotone_non_decreasing,
)
from hdrio.radiometry.levels import code_of, level_of, solve_levels
from hdrio.radiometry.weighting import WEIGHTING_METHODS, weighting_tutorial_hat
from hdrio.response.normal_equations import (
    Debevec1997Rows,
    IllConditioned,
    ReducedNormalSolver,
)
from hdrio.response.sampling import (
    DEFAULT_SAMPLES,
    SAMPLING_METHODS,
    matched_quantiles,
    sample_codes,
    tutorial_sample_count,
)
from hdrio.stack import distinct_exposures

if TYPE_CHECKING:
    import scipy.sparse as sp

DEFAULT_SMOOTHING = 50.0

SQRT_LEVELS_SLOPE = 0.1
"""Deep codes whose curve, solved on the brackets' matched quantiles
(:func:`deep_spacing`), has a slope against ``ln z`` within this of 1 in every channel
are a linear sensor's, and are solved at ``sqrt`` levels, not ``toe`` ones
(:mod:`hdrio.radiometry.levels`). Measured: the truth harness's linear ladders 0.99-1.00,
hand-held linear ladders (camera shake, a sun) 0.95-1.09; its other curves 0.66-0.70
(DoRF 120), 1.21-1.24 (DoRF 200), 1.41-1.45 (EMoR's mean) and steeper."""

_REFINED = 1e-12  # a refinement step this small (relative to g's range) ends refinement
_SVD_RCOND = 1e-13  # below this singular value ratio, the response is undetermined
_UNDETERMINED = (
    "the samples do not determine the camera response (the brackets show too little "
    "variation between exposures: a flat, constant or fully clipped scene?); use more or "
    "better-exposed brackets, or a saved response"
)

_ONE_EXPOSURE = (
    "every frame has the same exposure ({}): one exposure cannot show the camera "
    "response; merge such a burst through a known one (--response-from EXR, from an "
    "earlier merge; --response linear for linear data)"
)


def debevec1997_system(Z, log_exposures, smoothing: float, weights,
                       gauge_weight: float = 1.0) -> tuple[sp.csr_matrix, np.ndarray]:
    """The sparse matrix ``A`` and right-hand side ``b`` of the tutorial's objective.

    ``Z`` is ``(N, P)`` integer code levels in ``0 .. n-1``; ``log_exposures`` is ``(P,)``
    (or ``(N, P)``) ``ln dt_j``; ``weights`` is ``w`` at each of the ``n`` levels.
    ``gauge_weight`` scales the row ``g(n // 2) = 0`` (1 in the tutorial). Adding a
    constant to ``g`` and every ``ln E`` changes no other row, so that row is met
    exactly and its weight does not change the solution; only the conditioning.
    """
    import scipy.sparse as sp  # the tutorial's system only: the default solve is dense

    Z = np.asarray(Z, dtype=np.int64)
    weights = np.asarray(weights, dtype=np.float64)
    n = weights.size
    n_samples, n_brackets = Z.shape
    B = np.broadcast_to(np.asarray(log_exposures, dtype=np.float64), Z.shape)
    w = weights[Z].reshape(-1)
    data_rows = np.arange(n_samples * n_brackets)
    sample_of_row = np.repeat(np.arange(n_samples), n_brackets)

    z_inner = np.arange(1, n - 1)
    lam_w = smoothing * weights[z_inner]
    smooth_rows = n_samples * n_brackets + 1 + np.arange(n - 2)

    rows = np.concatenate([data_rows, data_rows, [n_samples * n_brackets],
                           np.repeat(smooth_rows, 3)])
    cols = np.concatenate([Z.reshape(-1), n + sample_of_row, [n // 2],
                           np.stack([z_inner - 1, z_inner, z_inner + 1], axis=1).reshape(-1)])
    values = np.concatenate([w, -w, [gauge_weight],
                             (lam_w[:, None] * np.array([1.0, -2.0, 1.0])).reshape(-1)])
    shape = (n_samples * n_brackets + 1 + n - 2, n + n_samples)
    A = sp.csr_matrix((values, (rows, cols)), shape=shape)
    b = np.zeros(shape[0])
    b[: n_samples * n_brackets] = w * B.reshape(-1)
    return A, b


def _solve_projected_svd(Z: np.ndarray, B: np.ndarray, smoothing: float,
                         weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same least-squares problem with ``ln E`` projected out, solved by SVD."""
    n = weights.size
    n_samples, n_brackets = Z.shape
    u = weights[Z]  # (N, P)
    norm2 = np.sum(u * u, axis=1)
    share = np.divide(u * u, norm2[:, None], out=np.zeros_like(u), where=norm2[:, None] > 0)
    rows = np.arange(n_samples * n_brackets).reshape(n_samples, n_brackets)
    data = np.zeros((n_samples * n_brackets, n))
    np.add.at(data, (rows, Z), u)
    # subtract u_ij * sum_k share_ik e_{Z_ik}: the projection of each sample's rows
    for k in range(n_brackets):
        np.add.at(data, (rows, np.broadcast_to(Z[:, k:k + 1], Z.shape)),
                  -u * share[:, k:k + 1])
    rhs_data = u * (B - np.sum(share * B, axis=1, keepdims=True))
    gauge = np.zeros((1, n))
    gauge[0, n // 2] = 1.0
    inner = np.arange(1, n - 1)
    smooth = np.zeros((n - 2, n))
    lam_w = smoothing * weights[inner]
    smooth[inner - 1, inner - 1] = lam_w
    smooth[inner - 1, inner] = -2.0 * lam_w
    smooth[inner - 1, inner + 1] = lam_w
    matrix = np.vstack([data, gauge, smooth])
    active = np.any(matrix != 0, axis=0)
    rhs = np.concatenate([rhs_data.reshape(-1), [0.0], np.zeros(n - 2)])
    solution, _, _, singular = np.linalg.lstsq(matrix[:, active], rhs, rcond=None)
    if singular.size == 0 or singular[-1] <= _SVD_RCOND * singular[0]:
        raise ResponseSolveError(_UNDETERMINED)
    g = np.zeros(n)
    g[active] = solution
    log_e = np.sum(share * (g[Z] - B), axis=1)
    return g, log_e


def g_solve_Debevec1997(Z, log_exposures, smoothing: float = DEFAULT_SMOOTHING,
                        weights=None, refinement_steps: int = 2
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Solve the tutorial's objective: ``(g, ln_E)`` for one channel.

    Parameters
    ----------
    Z
        ``(N, P)`` code levels of ``N`` samples in ``P`` brackets, integers in ``0 .. n-1``.
    log_exposures
        ``ln dt_j``, shape ``(P,)`` (or ``(N, P)`` as ``gsolve.m``'s ``B``).
    smoothing
        ``lambda``, the weight of the smoothness rows (50 in the tutorial).
    weights
        ``w(z)`` at each of the ``n`` levels (default: the tutorial's hat over 256 codes).
    refinement_steps
        At most this many steps of iterative refinement after the normal-equation solve;
        they stop early once a step changes nothing above ``1e-12`` of the range of
        ``g`` (with lambda up to 1e3 the first step is already that small).

    Returns
    -------
    g
        ``ln f^-1(z)`` at each level, natural log of relative exposure, ``g(n // 2) = 0``.
    ln_E
        Natural log of the relative irradiance of each sample.

    Raises
    ------
    ResponseSolveError
        If the samples leave the response undetermined.
    """
    if weights is None:
        weights = weighting_tutorial_hat(np.arange(256), 0, 255)
    weights = np.asarray(weights, dtype=np.float64)
    n = weights.size
    Z = np.ascontiguousarray(Z, dtype=np.intp)
    B = np.broadcast_to(np.asarray(log_exposures, dtype=np.float64), Z.shape)
    # The gauge row weighs like the heaviest column, not 1: with lambda in the thousands
    # (16-bit levels, many samples) a unit row left the reduced normal matrix near
    # singular (rcond ~ 1e-13) and sent the solve to the slow SVD path.
    rows = Debevec1997Rows(Z, B, weights, smoothing)
    try:
        solver = ReducedNormalSolver(rows)
    except IllConditioned:
        return _solve_projected_svd(Z, B, smoothing, weights)
    g, log_e = np.zeros(n), np.zeros(Z.shape[0])
    for step in range(1 + refinement_steps):  # the solve, then iterative refinement
        step_g, step_l = solver.solve(*rows.normal_residual(g, log_e))
        g += step_g
        log_e += step_l
        if step and max(np.abs(step_g).max(), np.abs(step_l).max(initial=0.0)) <= (
                _REFINED * np.ptp(g)):
            break
    return g, log_e


def response_Debevec1997(stack, smoothing: float = DEFAULT_SMOOTHING, *,
                         weighting: str = "Debevec1997", sampling: str = "stratified",
                         samples: int | None = None, exclude: np.ndarray | None = None,
                         seed: int = 0, levels: int | None = None, monotone: bool = True,
                         solve_identical_once: bool = True,
                         dropped: Callable[[np.ndarray], np.ndarray] | None = None,
                         spacing: str | None = None):
    """Recover a :class:`~hdrio.radiometry.curve.CameraResponse` from an exposure stack.

    Parameters
    ----------
    stack
        An :class:`~hdrio.stack.ExposureStack`.
    smoothing
        ``lambda`` (50 by default, as the tutorial), stated for the tutorial's sample count
        ``N_t`` (:func:`~hdrio.response.sampling.tutorial_sample_count`) and 256 levels,
        so that it means the same smoothing whatever the sampling:

        - ``N`` samples give ``N P`` data rows against a fixed number of smoothness rows;
          the smoothness rows are weighted by ``sqrt(N / N_t)`` to keep the balance (1
          with the tutorial's sampling, which is therefore reproduced exactly; about 2.4
          for the default 1000 samples of 7 brackets). Without it, more samples meant
          less smoothing and a noisier curve: on the truth harness's core stacks 300,
          1000 and 3000 samples gave 1.26, 1.36 and 1.55 % median error.
        - ``n`` levels weight them by ``(n / 256)^1.5``: second differences shrink as
          ``(256 / n)^2`` and their count grows as ``n / 256``, so this keeps the
          smoothing of a given curve independent of the level count.
    weighting
        A name in :data:`hdrio.radiometry.weighting.WEIGHTING_METHODS`.
    sampling, samples, exclude, seed
        Pixel selection (see :mod:`hdrio.response.sampling`); ``exclude`` is an
        ``(H, W)`` mask of pixels never to sample.
    levels
        Code levels solved for. Default (:func:`hdrio.radiometry.levels.solve_levels`):
        every code for 8-bit (256); 1024 for deeper codes (16-bit). The solved table is
        interpolated back to every code.
    spacing
        How the levels sit on the code axis (:data:`hdrio.radiometry.levels.SPACINGS`).
        Default: evenly when ``levels`` is given, else :func:`deep_spacing`'s (``toe``
        for deep codes, ``sqrt`` where they are a linear sensor's). A job decides it once,
        on the first stack it solves, and passes it to every re-solve
        (:func:`hdrio.job.stages.response_solver`).
    monotone
        Make each channel's ``g`` non-decreasing (a real response cannot fall).

    dropped
        Given the samples' codes ``(P, N, C)`` (bracket first), ``(P, N)`` booleans: the
        observations (one bracket at one pixel) left out whole, all their channels taken
        as saturated. A camera that mixes its channels after the clip biases every
        channel of an observation a clip reached
        (:class:`hdrio.merge.saturation.SolveFilter`). ``None``: only saturated codes
        weigh nothing.

    Channels whose samples are identical (greyscale stored as RGB) are solved once
    (unless ``solve_identical_once`` is false: the same curves, solved again);
    ``parameters["channels_solved"]`` says how many solves ran.
    """
    code_max = stack.code_max
    if distinct_exposures(stack.exposures) < 2:
        raise ResponseSolveError(_ONE_EXPOSURE.format(f"{stack.exposures[0]:g}"))
    if spacing is None:
        spacing = "even" if levels else deep_spacing(stack, smoothing, weighting)
    levels = levels or solve_levels(code_max)[0]
    sampler = SAMPLING_METHODS[sampling]
    indices = sampler(stack.codes, code_max, n_samples=samples or DEFAULT_SAMPLES,
                      exclude=exclude, seed=seed, n_levels=levels)
    if indices.size == 0:
        raise ResponseSolveError(
            "no usable samples: every pixel is clipped (0 or saturated) in all but at most "
            "one bracket, or excluded"
        )
    codes = sample_codes(stack.codes, indices)
    if dropped is not None:
        codes[np.asarray(dropped(codes.transpose(1, 0, 2))).T] = code_max
    sample_balance = math.sqrt(indices.size / tutorial_sample_count(stack.count))
    level_smoothing = smoothing * (levels / 256) ** 1.5 * sample_balance
    g_full, support_full, channels_solved = _solve_at(
        codes, stack.log_exposures, code_max, levels, level_smoothing,
        WEIGHTING_METHODS[weighting], monotone, solve_identical_once, spacing)
    return CameraResponse(
        log_inverse=g_full, code_max=code_max, supported=support_full,
        method="Debevec1997",
        parameters={"smoothing": float(smoothing), "level_smoothing": float(level_smoothing),
                    "weighting": weighting,
                    "sampling": sampling, "samples": int(indices.size), "levels": int(levels),
                    "spacing": spacing,
                    "monotone": bool(monotone), "sample_indices": indices,
                    "channels_solved": channels_solved,
                    **({} if dropped is None else {"dropped": repr(dropped)})},
    )


def deep_spacing(stack, smoothing: float = DEFAULT_SMOOTHING,
                 weighting: str = "Debevec1997") -> str:
    """How the levels of ``stack``'s response are spaced
    (:func:`hdrio.radiometry.levels.solve_levels`): ``even`` (every code) up to 10-bit
    codes; for deeper ones ``sqrt`` where they are a linear sensor's (a linear TIFF from
    a raw converter), else ``toe``.

    A linear sensor's: Debevec's solve at 256 ``toe`` levels on the brackets' matched
    quantiles (:func:`hdrio.response.sampling.matched_quantiles`, which camera shake does
    not blur: the pixel samples of an unregistered hand-held ladder gave slopes
    0.77-1.23) has a slope against ``ln z`` within :data:`SQRT_LEVELS_SLOPE` of 1 in
    every channel. A solve that the quantiles cannot support says ``toe``."""
    spacing = solve_levels(stack.code_max)[1]
    if spacing != "toe":
        return spacing
    samples = matched_quantiles(stack.codes)
    level_smoothing = smoothing * math.sqrt(
        samples.shape[0] / tutorial_sample_count(stack.count))
    try:
        g, _, _ = _solve_at(samples, stack.log_exposures, stack.code_max, 256,
                            level_smoothing, WEIGHTING_METHODS[weighting], True, True, "toe")
    except ResponseSolveError:
        return "toe"
    slopes, _ = log_fit(g, stack.code_max)
    return "sqrt" if np.all(np.abs(slopes - 1.0) <= SQRT_LEVELS_SLOPE) else "toe"


def _solve_at(codes: np.ndarray, log_exposures: np.ndarray, code_max: int, levels: int,
              level_smoothing: float, weighting: Callable, monotone: bool,
              solve_identical_once: bool, spacing: str) -> tuple[np.ndarray, np.ndarray, int]:
    """Solve each channel of the samples' ``codes`` ``(N, P, C)`` at ``levels`` levels
    spaced ``spacing`` (:mod:`hdrio.radiometry.levels`) with lambda ``level_smoothing``:
    ``g`` and its support at every code, and how many channels were solved (identical
    ones once)."""
    Z = codes
    if levels != code_max + 1:
        Z = np.rint(level_of(Z, code_max, levels, spacing)).astype(np.int64)
    at = code_of(levels, code_max, spacing)
    weights = weighting(at, 0.0, float(code_max))
    if spacing != "even":
        # Levels below the first evenly spaced one (64 codes of 65535) carry no weight,
        # as the even levels had none there: the hat gives them under 0.2 % of the middle,
        # and the curve below them (a ramp only their tiny smoothness rows pin) made the
        # normal equations ill-conditioned (rcond under 1e-12: the SVD path, 4 s a solve).
        weights[at < code_max / (levels - 1)] = 0.0
    anchor = levels // 2
    tables, supported, solved = [], [], {}
    for c in range(Z.shape[2]):
        key = Z[:, :, c].tobytes() if solve_identical_once else c
        if key not in solved:
            touched = np.bincount(Z[:, :, c].reshape(-1),
                                  weights=weights[Z[:, :, c]].reshape(-1), minlength=levels) > 0
            _check_coverage(touched, None if spacing == "even" else at)
            g, _ = g_solve_Debevec1997(Z[:, :, c], log_exposures, level_smoothing, weights)
            determined = _determined_levels(weights, touched)
            g = fill_unsupported(g, determined)
            if monotone:
                g = monotone_non_decreasing(g, anchor)
            solved[key] = (g, touched)
        g, touched = solved[key]
        tables.append(g)
        supported.append(touched)
    g_levels = np.stack(tables, axis=1)
    support_levels = np.stack(supported, axis=1)
    if levels == code_max + 1:
        return g_levels, support_levels, len(solved)
    position = level_of(np.arange(code_max + 1), code_max, levels, spacing)
    g_full = np.stack([np.interp(position, np.arange(levels), g_levels[:, c])
                       for c in range(g_levels.shape[1])], axis=1)
    support_full = support_levels[np.rint(position).astype(np.int64)]
    if spacing != "even":  # the gauge's level is not code_max's middle: g(z_mid) = 0
        g_full -= g_full[(code_max + 1) // 2]
    return g_full, support_full, len(solved)


MIN_SUPPORTED_LEVELS = 16
MAX_GAP_FRACTION = 1 / 2


def _check_coverage(touched: np.ndarray, at: np.ndarray | None = None) -> None:
    """Refuse samples that pin g at only a few tones (a grey card, a single pixel).

    Debevec's solve needs the samples to chain the code range together; with a handful
    of tones (under 16 levels), or a gap of half the range between data, the smoothness
    term alone would invent the curve between them. ``at``: the code of each level when
    they are not evenly spaced (:mod:`hdrio.radiometry.levels`), whose gaps are measured
    in codes (half of ``sqrt`` levels lie in the range's bottom quarter: a 12-bit
    ladder's samples 537 levels apart were codes 135 and 2045, 47 % of its range).
    """
    levels = np.flatnonzero(touched)
    if at is None:
        gap = int(np.max(np.diff(levels))) if levels.size > 1 else touched.size
        wide, span = gap > MAX_GAP_FRACTION * touched.size, f"{gap} of {touched.size}"
    else:
        gap = float(np.max(np.diff(at[levels]))) if levels.size > 1 else float(at[-1])
        wide, span = gap > MAX_GAP_FRACTION * at[-1], f"{gap:.0f} codes of {at[-1]:.0f}"
    if levels.size < MIN_SUPPORTED_LEVELS or wide:
        raise ResponseSolveError(
            f"the samples show too few distinct tones to recover a response ({levels.size} "
            f"code levels, largest gap {span}): shoot a scene with more tonal variety or "
            "more brackets, or use a saved response"
        )


def _determined_levels(weights: np.ndarray, touched: np.ndarray) -> np.ndarray:
    """Levels some equation reaches: a weighted data row, or an active smoothness row."""
    reached = touched.copy()
    active = np.flatnonzero(weights[1:-1] > 0) + 1
    for offset in (-1, 0, 1):
        reached[active + offset] = True
    return reached
