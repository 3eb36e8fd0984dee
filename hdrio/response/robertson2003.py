"""Robertson, Borman & Stevenson (2003): the response as a maximum-likelihood estimate,
refining Debevec's solution with the stack's noise model (``--response Robertson2003``).

Each observation ``z_ij`` (pixel ``i``, bracket ``j``) is modelled as ``f^-1(z_ij) =
dt_j x_i + noise``, with the variance of :mod:`hdrio.radiometry.noise` (shot, read and code
noise). Maximising the likelihood alternates two closed-form steps (the paper's
Gauss-Seidel relaxation):

1. each pixel's radiance ``x_i`` is the inverse-variance weighted mean of its brackets'
   estimates ``f^-1(z_ij) / dt_j``;
2. each code's ``f^-1(m)`` is the mean of ``dt_j x_i`` over the observations showing
   ``m`` (every observation of a code has the same variance, so the mean is the ML
   update); ``x_i`` leaves observation ``j`` out, so a code is not fitted to itself.

It starts from :func:`~hdrio.response.debevec1997.response_Debevec1997` (the tutorial's
objective) and runs on the noise fit's grid of pixels (up to 16384 per bracket, where
Debevec's solve takes 1000): "refine the Debevec solution on many more pixels with the
same noise model". Observations within two standard deviations of black or saturation
stay out (:func:`hdrio.radiometry.noise.usable_codes`), as in the merge. ``g(z_mid) = 0``,
monotone, and codes with too few observations keep Debevec's values.

It is not the default: on the truth harness's stacks it measures worse than Debevec's
solve (docs/accuracy.md). With exposures an exact power of one ratio apart the
likelihood is flat along a wave periodic in ``ln X`` (docs/method.md, "The floor
left"), which the smoothness term of Debevec's objective settles and the likelihood
alone cannot; and the mean of ``dt_j x_i`` over a code's observations is the
conditional mean of the exposure given the code, which the scene's own distribution of
exposures pulls away from ``f^-1(m)`` where the slope is steep.

References
----------
Robertson, M. A., Borman, S., & Stevenson, R. L. (2003). Estimation-theoretic approach
to dynamic range enhancement using multiple exposures. Journal of Electronic Imaging
12(2), 219-228. doi:10.1117/1.1557695
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from hdrio.radiometry.curve import CameraResponse, monotone_non_decreasing
from hdrio.radiometry.levels import level_of
from hdrio.response.debevec1997 import DEFAULT_SMOOTHING, response_Debevec1997
from hdrio.stack import exposure_columns

DEFAULT_ITERATIONS = 3
"""Alternations at most. On the truth harness's ladders (exposures a power of one ratio
apart) the alternation does not settle: after the first steps it drifts along the
likelihood's flat direction (Desk, DoRF 0: median error 0.56 % with Debevec's curve,
0.57 / 0.58 / 0.60 / 0.71 % after 1 / 2 / 5 / 20 alternations)."""

TOLERANCE = 1e-4
"""Stop when no code's ``g`` moves by more than this (natural log units)."""

MIN_OBSERVATIONS = 8
"""A code needs this many usable observations to be re-estimated."""


def response_Robertson2003(stack, smoothing: float = DEFAULT_SMOOTHING, *,
                           weighting: str = "Debevec1997", sampling: str = "stratified",
                           samples: int | None = None, exclude: np.ndarray | None = None,
                           seed: int = 0, levels: int | None = None, monotone: bool = True,
                           solve_identical_once: bool = True,
                           iterations: int = DEFAULT_ITERATIONS,
                           dropped: Callable[[np.ndarray], np.ndarray] | None = None,
                           spacing: str | None = None) -> CameraResponse:
    """Debevec's response refined by maximum likelihood (module docstring).

    The parameters other than ``iterations`` are
    :func:`~hdrio.response.debevec1997.response_Debevec1997`'s, for the starting solve;
    ``exclude`` (``(H, W)``, pixels never to sample) also keeps pixels out of the
    refinement, and ``dropped`` leaves the observations it names out of both whole.
    ``parameters["iterations"]`` says how many alternations ran.
    """
    # Imported here: hdrio.radiometry.noise imports this package's curve module.
    from hdrio.io.staging import candidate_stride
    from hdrio.radiometry.noise import noise_encoding, observation_variance, usable_codes
    from hdrio.radiometry.noise_fit import fit_noise, noise_grid

    start = response_Debevec1997(stack, smoothing, weighting=weighting, sampling=sampling,
                                 samples=samples, exclude=exclude, seed=seed, levels=levels,
                                 monotone=monotone,
                                 solve_identical_once=solve_identical_once, dropped=dropped,
                                 spacing=spacing)
    grid = noise_grid(stack.codes)  # (P, n, C)
    if dropped is not None:  # saturated codes are never usable
        grid[np.asarray(dropped(grid))] = stack.code_max
    noise = fit_noise(stack.codes, stack.exposures, start, grid=grid,
                      encoding=noise_encoding(stack.files, stack.code_max))
    keep = None
    if exclude is not None:
        stride = candidate_stride(*stack.shape[:2])
        keep = ~np.asarray(exclude, dtype=bool)[::stride, ::stride].reshape(-1)
    times = np.broadcast_to(exposure_columns(stack.channel_exposures),
                            (stack.count, stack.shape[2]))  # (P, C)
    anchor = (stack.code_max + 1) // 2
    g = np.array(start.log_inverse, dtype=np.float64)
    levels = int(start.parameters["levels"])
    spacing = str(start.parameters.get("spacing", "even"))
    ran = 0
    while ran < iterations:
        ran += 1
        response = replace(start, log_inverse=g)
        variance = observation_variance(response, stack.channel_exposures, noise)
        usable = usable_codes(response, noise)
        updated = np.stack([_update(grid[:, :, c], g[:, c], times[:, c], variance[:, c],
                                    usable[:, c], keep, anchor, levels, spacing, monotone)
                            for c in range(g.shape[1])], axis=1)
        change = float(np.max(np.abs(updated - g)))
        g = updated
        if change <= TOLERANCE:
            break
    return CameraResponse(
        log_inverse=g, code_max=start.code_max, supported=start.supported,
        method="Robertson2003",
        parameters={**start.parameters, "iterations": ran, "refined_pixels": grid.shape[1],
                    "start": "Debevec1997"})


def _update(Z: np.ndarray, g: np.ndarray, times: np.ndarray, variance: np.ndarray,
            usable: np.ndarray, keep: np.ndarray | None, anchor: int, levels: int,
            spacing: str, monotone: bool) -> np.ndarray:
    """One alternation for one channel: ``Z`` ``(P, n)`` codes, ``g`` ``(codes,)``,
    ``times`` ``(P,)``, ``variance`` ``(P, codes)``, ``usable`` ``(codes,)``.

    Codes are pooled into Debevec's solve's levels (``levels``, ``spacing``: every code
    its own at 8 bits; :mod:`hdrio.radiometry.levels`): each bin with enough observations
    moves ``g`` at its observations' mean code to the log of their mean ``dt_j x_i``; the
    correction is interpolated between bins (held at the ends) and ``g(anchor) = 0``
    again.
    """
    Z = Z.astype(np.intp)
    X = np.exp(g)
    estimate = X[Z] / times[:, None]  # (P, n): each bracket's radiance estimate
    weight = np.where(usable[Z], 1.0 / np.take_along_axis(variance, Z, axis=1), 0.0)
    if keep is not None:
        weight *= keep[None, :]
    total, norm = (weight * estimate).sum(axis=0), weight.sum(axis=0)
    others = norm[None, :] - weight  # leave-one-out: bracket j's own term taken away
    observed = (weight > 0) & (others > 0)
    radiance = np.divide(total[None, :] - weight * estimate, others,
                         out=np.zeros_like(estimate), where=observed)
    code_max = g.size - 1
    codes = Z[observed]
    bins = np.rint(level_of(codes, code_max, levels, spacing)).astype(np.intp)
    count = np.bincount(bins, minlength=levels)
    exposure = np.bincount(bins, weights=(times[:, None] * radiance)[observed],
                           minlength=levels)
    at_code = np.bincount(bins, weights=codes, minlength=levels)
    refined = count >= MIN_OBSERVATIONS
    if np.count_nonzero(refined) < 2:
        return g
    mean_code = at_code[refined] / count[refined]
    mean_exposure = exposure[refined] / count[refined]
    if np.any(mean_exposure <= 0):
        return g
    correction = np.log(mean_exposure) - np.interp(mean_code, np.arange(g.size), g)
    updated = g + np.interp(np.arange(g.size), mean_code, correction)
    updated -= updated[anchor]
    return monotone_non_decreasing(updated, anchor) if monotone else updated
