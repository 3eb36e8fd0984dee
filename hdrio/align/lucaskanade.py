"""Sub-pixel refinement: inverse-compositional Gauss-Newton (Lucas-Kanade) on a pyramid.

The images are the brackets' log relative radiance (:mod:`hdrio.align.pyramid`): a still
scene gives the same values in every bracket wherever both are well exposed, up to a
constant (exposure metadata and response errors), which is estimated alongside the warp.
The warp ``W`` maps reference pixels to moving pixels, ``x_mov = W x_ref`` (3x3,
homogeneous), one of:

``translation`` (2 parameters), ``euclidean`` (translation + rotation, 3),
``homography`` (8).

Inverse compositional (Baker & Matthews 2004): the steepest-descent images come from
the reference's gradient, computed once per level, at the :data:`POINTS` strongest
gradients; each iteration samples the moving image at those points only, so a level
costs the same at any image size. Residuals are weighted by Huber's function (moving
objects, clipped edges), and a 2x pyramid takes the estimate from coarse to fine.

References
----------
Lucas, B. D., & Kanade, T. (1981). An iterative image registration technique with an
application to stereo vision. IJCAI, 674-679.
Baker, S., & Matthews, I. (2004). Lucas-Kanade 20 years on: a unifying framework.
International Journal of Computer Vision, 56(3), 221-255.
"""

from __future__ import annotations

import numpy as np
from numba import njit

MODELS = ("translation", "euclidean", "homography")

POINTS = 40_000
"""Reference pixels used per level (the strongest gradients)."""

MIN_POINTS = 200
"""A level with fewer usable reference pixels is skipped."""

ITERATIONS = 20
CONVERGED = 1e-3
"""Stop the finest level when an update moves no corner by more than this many of its
pixels (coarser levels: twenty times this)."""

HUBER = 1.345


def scaling(factor: float) -> np.ndarray:
    """``A`` with ``x_fine = A x_coarse`` for pixel centres of a ``factor``-times block
    average."""
    offset = (factor - 1.0) / 2.0
    return np.array([[factor, 0.0, offset], [0.0, factor, offset], [0.0, 0.0, 1.0]])


def rescale(warp: np.ndarray, factor: float) -> np.ndarray:
    """``warp`` on the coarse pixel grid expressed on the ``factor``-times finer grid."""
    a = scaling(factor)
    return a @ warp @ np.linalg.inv(a)


def translation(dx: float, dy: float) -> np.ndarray:
    """The 3x3 warp ``x -> x + (dx, dy)``."""
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])


def _update(model: str, delta: np.ndarray) -> np.ndarray:
    if model == "translation":
        return translation(delta[0], delta[1])
    if model == "euclidean":
        c, s = np.cos(delta[2]), np.sin(delta[2])
        return np.array([[c, -s, delta[0]], [s, c, delta[1]], [0.0, 0.0, 1.0]])
    p = delta
    return np.array([[1.0 + p[0], p[2], p[4]], [p[1], 1.0 + p[3], p[5]], [p[6], p[7], 1.0]])


def _steepest_descent(model: str, gx, gy, u, v) -> np.ndarray:
    if model == "translation":
        columns = [gx, gy]
    elif model == "euclidean":
        columns = [gx, gy, -v * gx + u * gy]
    else:
        columns = [u * gx, u * gy, v * gx, v * gy, gx, gy,
                   -u * (u * gx + v * gy), -v * (u * gx + v * gy)]
    return np.stack([*columns, np.ones_like(gx)], axis=1)  # the last: the constant


@njit(cache=True, nogil=True)
def _sample(image, valid, xs, ys, values, good):  # pragma: no cover - compiled
    """Bilinear ``image`` at ``(xs, ys)``; ``good`` where inside and all four neighbours
    are valid."""
    height, width = image.shape
    for i in range(xs.size):
        x, y = xs[i], ys[i]
        if not (0.0 <= x <= width - 1.0 and 0.0 <= y <= height - 1.0):
            good[i] = False
            values[i] = 0.0
            continue
        x0 = min(int(x), width - 2)
        y0 = min(int(y), height - 2)
        fx, fy = x - x0, y - y0
        good[i] = (valid[y0, x0] & valid[y0, x0 + 1] & valid[y0 + 1, x0]
                   & valid[y0 + 1, x0 + 1])
        values[i] = ((1.0 - fy) * ((1.0 - fx) * image[y0, x0] + fx * image[y0, x0 + 1])
                     + fy * ((1.0 - fx) * image[y0 + 1, x0] + fx * image[y0 + 1, x0 + 1]))


def _apply(warp: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    w = warp[2, 0] * x + warp[2, 1] * y + warp[2, 2]
    return ((warp[0, 0] * x + warp[0, 1] * y + warp[0, 2]) / w,
            (warp[1, 0] * x + warp[1, 1] * y + warp[1, 2]) / w)


def corner_motion(warp: np.ndarray, height: float, width: float) -> float:
    """Largest distance (pixels) by which ``warp`` moves a corner of the image."""
    x = np.array([0.0, width - 1.0, 0.0, width - 1.0])
    y = np.array([0.0, 0.0, height - 1.0, height - 1.0])
    wx, wy = _apply(warp, x, y)
    return float(np.max(np.hypot(wx - x, wy - y)))


def _level(reference, ref_valid, moving, mov_valid, warp, model, points, converged):
    """One level: ``warp`` (pixels of this level) refined, from at most ``points`` pixels,
    until an update moves no corner by ``converged`` pixels."""
    h, w = reference.shape
    gy, gx = np.gradient(reference)
    usable = ref_valid.copy()
    usable[[0, -1], :] = False
    usable[:, [0, -1]] = False
    usable[1:-1, 1:-1] &= (ref_valid[:-2, 1:-1] & ref_valid[2:, 1:-1] & ref_valid[1:-1, :-2]
                           & ref_valid[1:-1, 2:])
    index = np.flatnonzero(usable)
    if index.size < MIN_POINTS:
        return warp  # too little in common at this level: the finer levels decide
    strength = (gx * gx + gy * gy).reshape(-1)[index]
    if index.size > points:
        index = index[np.argpartition(strength, -points)[-points:]]
    py, px = np.divmod(index, w)
    px, py = px.astype(np.float64), py.astype(np.float64)
    template = reference.reshape(-1)[index].astype(np.float64)
    # Normalised coordinates (u, v in [-1, 1]) condition the Jacobians.
    half = max(h, w) / 2.0
    centre_x, centre_y = (w - 1) / 2.0, (h - 1) / 2.0
    to_pixels = np.array([[half, 0.0, centre_x], [0.0, half, centre_y], [0.0, 0.0, 1.0]])
    to_normal = np.linalg.inv(to_pixels)
    u, v = (px - centre_x) / half, (py - centre_y) / half
    sd = _steepest_descent(model, gx.reshape(-1)[index] * half,
                           gy.reshape(-1)[index] * half, u, v)
    warp_n = to_normal @ warp @ to_pixels
    bias = 0.0
    sampled = np.empty(px.size)
    good = np.empty(px.size, np.bool_)
    for _ in range(ITERATIONS):
        mx, my = _apply(to_pixels @ warp_n @ to_normal, px, py)
        _sample(moving, mov_valid, mx, my, sampled, good)
        if np.count_nonzero(good) < MIN_POINTS:
            break
        error = sampled - template - bias
        spread = error[good][::8]  # the median of an eighth: the same scale, 8x cheaper
        scale = 1.4826 * np.median(np.abs(spread - np.median(spread))) + 1e-6
        weight = np.where(good, np.minimum(1.0, HUBER * scale / (np.abs(error) + 1e-12)), 0.0)
        weighted = sd * weight[:, None]
        hessian = weighted.T @ sd
        try:
            delta = np.linalg.solve(hessian, weighted.T @ error)
        except np.linalg.LinAlgError:
            break
        bias += delta[-1]
        step = _update(model, delta[:-1])
        warp_n = warp_n @ np.linalg.inv(step)
        if corner_motion(to_pixels @ step @ to_normal, h, w) < converged:
            break
    return to_pixels @ warp_n @ to_normal


def strongest(reference: np.ndarray, ref_valid: np.ndarray, points: int = POINTS
              ) -> np.ndarray:
    """Flat indices of the ``points`` strongest gradients of ``reference`` where valid."""
    gy, gx = np.gradient(reference)
    index = np.flatnonzero(ref_valid)
    if index.size > points:
        strength = (gx * gx + gy * gy).reshape(-1)[index]
        index = index[np.argpartition(strength, -points)[-points:]]
    return index


def strongest_usable(reference: np.ndarray, ref_valid: np.ndarray, moving: np.ndarray,
                     mov_valid: np.ndarray, warp: np.ndarray, points: int = POINTS
                     ) -> np.ndarray:
    """:func:`strongest` among the pixels of ``ref_valid`` where the moving image is usable
    under ``warp`` (:func:`residuals`' test): the points to measure that warp's misfit on
    alone, where those of ``ref_valid`` could all lie where the moving bracket clips (a
    longer bracket beside the edges of a bright sky)."""
    index = np.flatnonzero(ref_valid)
    py, px = np.divmod(index, ref_valid.shape[1])
    mx, my = _apply(warp, px.astype(np.float64), py.astype(np.float64))
    good = np.empty(index.size, np.bool_)
    _sample(moving, mov_valid, mx, my, np.empty(index.size), good)
    usable = np.zeros(ref_valid.size, np.bool_)
    usable[index[good]] = True
    return strongest(reference, usable.reshape(ref_valid.shape), points)


def residuals(reference: np.ndarray, ref_valid: np.ndarray, moving: np.ndarray,
              mov_valid: np.ndarray, warps, points: int = POINTS,
              index: np.ndarray | None = None) -> list[float]:
    """The robust misfit of each of ``warps`` on one level: the median absolute deviation
    of ``moving(W x) - reference(x)`` (``ln`` units) over the ``points`` strongest
    reference gradients (``index``: those points, when already found,
    :func:`strongest`), all over the same points: those where the moving image is usable
    under every warp (``inf`` each when too few are). A misfit over the points one warp
    keeps and another loses compares two samples, not two warps: no motion kept the
    points inside the moving image's usable regions, easy ones, and on a hand-held JPEG
    ladder its coarse misfit came out 0.065 against 0.102 for the true warp."""
    h, w = reference.shape
    if index is None:
        index = strongest(reference, ref_valid, points)
    py, px = np.divmod(index, w)
    px, py = px.astype(np.float64), py.astype(np.float64)
    values = np.empty((len(warps), index.size))
    common = np.ones(index.size, np.bool_)
    good = np.empty(index.size, np.bool_)
    for k, warp in enumerate(warps):
        mx, my = _apply(warp, px, py)
        _sample(moving, mov_valid, mx, my, values[k], good)
        common &= good
    if np.count_nonzero(common) < MIN_POINTS:
        return [np.inf] * len(warps)
    target = reference.reshape(-1)[index][common]
    out = []
    for k in range(len(warps)):
        error = values[k][common] - target
        out.append(float(np.median(np.abs(error - np.median(error)))))
    return out


def refine_LucasKanade(references: list[tuple[np.ndarray, np.ndarray]],
                       movings: list[tuple[np.ndarray, np.ndarray]], warp: np.ndarray,
                       model: str = "euclidean") -> np.ndarray:
    """Refine ``warp`` (3x3, pixels of level 0) coarse to fine.

    Parameters
    ----------
    references, movings
        Pyramids, finest (level 0) first: ``(log radiance, valid)`` per level, each level
        a 2x block average of the one before.
    warp
        Initial ``x_mov = W x_ref`` on level 0's pixel grid.
    model
        One of :data:`MODELS`.

    Returns
    -------
    The refined warp on level 0's grid.
    """
    if model not in MODELS:
        raise ValueError(f"alignment model must be one of {MODELS}, not {model!r}")
    top = len(references) - 1
    warp = rescale(warp, 0.5**top)
    for k in range(top, -1, -1):
        (ref, ref_valid), (mov, mov_valid) = references[k], movings[k]
        # Coarse levels only need to bring the next within its reach: fewer points, a
        # looser stop (a quarter of the iterations at 1.5 MP, the same result).
        warp = _level(ref, ref_valid, mov, mov_valid, warp, model,
                      POINTS if k == 0 else POINTS // 4, CONVERGED * (20.0 if k else 1.0))
        if k > 0:
            warp = rescale(warp, 2.0)
    return warp / warp[2, 2]
