"""Alignment and deghosting as a merge runs them (``--align``, ``--deghost``): a stack and
its response in; the warped stack and :class:`Motion` (the transforms, the keep weights
of each bracket) out. The re-merge that reads them is the job's
(:func:`hdrio.job.radiance.remerge_motion`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from hdrio.align.deghost import (
    CELL,
    Deghosting,
    consistency_variance,
    deghost,
)
from hdrio.align.quick import looks_still, usable_masks
from hdrio.align.registration import (
    Alignment,
    align_stack,
    best_exposed_bracket,
    linear_tables,
    reference_bracket,
    register,
)
from hdrio.align.resolve import solve_on_sample
from hdrio.align.warp import clipped_elsewhere, coverage, seen_elsewhere
from hdrio.errors import HdrioError
from hdrio.io.staging import gather_pixels
from hdrio.parallel import on_threads
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import NoiseModel
from hdrio.radiometry.noise_fit import fit_noise
from hdrio.stack import ExposureStack


@dataclass
class Motion:
    """What alignment and deghosting did, for the summary and the header.

    Attributes
    ----------
    alignment
        The measured warps (``None`` with ``--align off``).
    warped
        Whether the brackets were resampled (``auto`` skips it when every bracket is
        within :data:`hdrio.align.registration.WITHIN` pixels).
    deghosting
        Keep weights and the fraction deghosted (``None`` with ``--deghost off``).
    uncovered
        Fraction of pixels some warped bracket does not cover (dropped there).
    best_exposed
        :func:`hdrio.align.registration.best_exposed_bracket`, when the still check has
        found it (the deghosting test's reference: not looked for twice).
    """

    alignment: Alignment | None = None
    warped: bool = False
    deghosting: Deghosting | None = None
    uncovered: float = 0.0
    best_exposed: int | None = None
    too_small: str = ""
    """Why ``--align auto`` registered nothing (brackets too small), or ``""``."""
    keep: np.ndarray | None = None
    """``(P, rows, cols)`` keep weights on cells of :data:`hdrio.align.deghost.CELL`
    pixels, or ``None`` when no bracket is dropped anywhere."""
    unregistered: np.ndarray | None = None
    """``(rows, cols)`` cells that only a bracket which could not be registered sees
    (merged unwarped there: the motion layer flags them), or ``None``."""

    def unregistered_fraction(self) -> float:
        """The fraction of the image only an unregistered bracket sees."""
        return 0.0 if self.unregistered is None else float(np.mean(self.unregistered))


MIN_REGISTER_SIDE = 8
"""Brackets narrower or shorter than this are not registered: the still check's sample
grid has no two rows (a 1 x 1000 strip, a 5 x 5 thumbnail) and a warp measured on so few
pixels means nothing."""


FALLING = 16 / 255
"""A still pixel's code never falls as the exposure grows (a response is monotone); one
that falls by more than this fraction of the range from a shorter bracket to a longer
one, beyond noise and JPEG's ringing, saw something move. (Still stacks: frobisher,
the generated PNG, 16-bit and night stacks none of their response's samples; the
generated JPEG tripod stack and ghost/'s 0.4 %.)"""
FALLING_SAMPLES = 0.02
"""When at least this fraction of the response's samples fall (:data:`FALLING`) and the
test found nothing, the response is solved again without them and the test run again
(:func:`deghost_step`): a mover covering 5 % of the frame makes about 6 % of them."""


def falling(codes: np.ndarray, code_max: int) -> np.ndarray:
    """``(...)`` bool of ``codes`` ``(P, ..., C)`` sorted by exposure: some channel falls
    by more than :data:`FALLING` of the range from a shorter bracket to a longer one."""
    wide = np.int32 if code_max > 255 else np.int16  # room for a code minus the margin
    margin = wide(round(FALLING * code_max))
    highest = codes[0].astype(wide)
    out = np.zeros(codes.shape[1:-1], bool)
    for j in range(1, codes.shape[0]):
        current = codes[j].astype(wide)
        below = current < highest - margin
        for c in range(below.shape[-1]):  # by channel: faster than any(axis=-1)
            out |= below[..., c]
        np.maximum(highest, current, out=highest)
    return out


def falling_fraction(stack: ExposureStack, response: CameraResponse,
                     found: np.ndarray | None = None) -> float:
    """The fraction of the pixels ``response`` was solved on (its ``sample_indices``;
    those outside ``found``, ``(H, W)``, when given) whose codes fall with exposure
    (:func:`falling`); 0 without such samples."""
    indices = response.parameters.get("sample_indices")
    if indices is None or len(indices) == 0:
        return 0.0
    indices = np.asarray(indices)
    if found is not None:
        indices = indices[~found.reshape(-1)[indices]]
        if indices.size == 0:
            return 0.0
    samples = gather_pixels(stack.codes, indices)  # (P, N, C)
    return float(np.mean(falling(samples, stack.code_max)))


FALLING_LEFT = 0.005
"""When this fraction of the response's samples outside what the first test found fall
(:data:`FALLING`), the falling pixels are left out of the re-solve too
(:func:`deghost_step`; the generated movers that needed it: 0.60-1.08 %; the real
stacks' canal, ghost/ and memorial with ``--exclude-color``: 0 %). Reading every
pixel's codes (:func:`falling_pixels`) costs 1.6 s at 7 x 24 MP, so it is not done
where none fall."""
RESOLVES = 2
"""The most times :func:`deghost_step` solves the response again without what it
found moving."""
GROWN = 1.1
"""... again only when the last test found more than this times what the one before
it dropped."""


def falling_pixels(codes: np.ndarray, code_max: int) -> np.ndarray:
    """``(H, W)``: the pixels whose codes fall with exposure (:func:`falling`), grown by
    a cell (a mover's edge blurs into its neighbours); rows shared among the threads,
    every bracket's codes of a pixel read together (NumPy's pass per bracket, on one
    thread in bands of rows, took 0.7 s at 7 x 24 MP)."""
    height, width = codes.shape[1:3]
    fell = np.zeros((height, width), np.uint8)
    on_threads(_falling_rows, height, codes, int(round(FALLING * code_max)), fell)
    across = np.empty_like(fell)
    on_threads(_grow_across, height, fell, CELL, across)
    del fell
    grown = np.empty((height, width), np.bool_)
    on_threads(_grow_down, height, across, CELL, grown)
    return grown


@njit(cache=True, nogil=True)
def _grow_across(start, stop, mask, radius, out):  # pragma: no cover - compiled
    """Rows ``start .. stop - 1``: 1 where ``mask`` has a 1 within ``radius`` columns (a
    running count over the window)."""
    width = mask.shape[1]
    for y in range(start, stop):
        count = 0
        for x in range(min(radius, width)):
            count += mask[y, x]
        for x in range(width):
            if x + radius < width:
                count += mask[y, x + radius]
            if x - radius - 1 >= 0:
                count -= mask[y, x - radius - 1]
            out[y, x] = count > 0


@njit(cache=True, nogil=True)
def _grow_down(start, stop, across, radius, out):  # pragma: no cover - compiled
    """Rows ``start .. stop - 1``: ``across`` (:func:`_grow_across`) grown by ``radius``
    rows: with it, ``scipy.ndimage.maximum_filter(mask, 2 radius + 1, mode="constant")``
    (0.19 s at 24 MP on one thread)."""
    height, width = across.shape
    for y in range(start, stop):
        for x in range(width):
            out[y, x] = False
        for yy in range(max(0, y - radius), min(height, y + radius + 1)):
            for x in range(width):
                out[y, x] |= across[yy, x] != 0


@njit(cache=True, nogil=True)
def _falling_rows(start, stop, codes, margin, out):  # pragma: no cover - compiled
    """Rows ``start .. stop - 1`` of :func:`falling` for every pixel of ``codes``
    ``(P, H, W, C)``, into ``out`` (1 where some channel falls)."""
    count, _, width, channels = codes.shape
    highest = np.empty(channels, np.int64)
    for y in range(start, stop):
        for x in range(width):
            fell = False
            if channels == 3:  # spelt out, the running maxima in registers: 2.5x faster
                h0 = np.int64(codes[0, y, x, 0])
                h1 = np.int64(codes[0, y, x, 1])
                h2 = np.int64(codes[0, y, x, 2])
                for j in range(1, count):
                    z0 = np.int64(codes[j, y, x, 0])
                    z1 = np.int64(codes[j, y, x, 1])
                    z2 = np.int64(codes[j, y, x, 2])
                    fell |= (z0 < h0 - margin) | (z1 < h1 - margin) | (z2 < h2 - margin)
                    h0, h1, h2 = max(h0, z0), max(h1, z1), max(h2, z2)
                out[y, x] = fell
                continue
            for c in range(channels):
                highest[c] = codes[0, y, x, c]
            for j in range(1, count):
                for c in range(channels):
                    z = np.int64(codes[j, y, x, c])
                    fell |= z < highest[c] - margin
                    highest[c] = max(highest[c], z)
            out[y, x] = fell


def _pixels(cells: np.ndarray, height: int, width: int) -> np.ndarray:
    """``(H, W)``: ``cells`` (of :data:`hdrio.align.deghost.CELL` pixels) at full size."""
    return np.repeat(np.repeat(cells, CELL, axis=0), CELL, axis=1)[:height, :width]


def align_step(stack: ExposureStack, response: CameraResponse, mode: str,
               solve: Callable[[ExposureStack, np.ndarray], CameraResponse] | None,
               in_place: bool = False, skip_warp: bool = True,
               excluded: np.ndarray | None = None
               ) -> tuple[ExposureStack, CameraResponse, Motion]:
    """Measure and (unless ``auto`` finds nothing moved) warp; ``solve`` re-solves the
    response on the aligned brackets (``None``: keep ``response``, e.g. a saved one).
    ``skip_warp`` false (``--no-skip warp``) makes ``auto`` measure fully and warp.
    ``excluded``: ``(P, H, W)`` observations the merge leaves out (``--mask``,
    ``--exclude-color``), each in its bracket's own frame: neither the still check nor
    the registration reads them (a masked block of garbage is not motion)."""
    motion = Motion()
    if mode == "off" or stack.count < 2:
        return stack, response, motion
    height, width = stack.codes.shape[1:3]
    if min(height, width) < MIN_REGISTER_SIDE:
        why = (f"the brackets are {width}x{height} pixels, too small to register (at "
               f"least {MIN_REGISTER_SIDE} on each side)")
        if mode != "auto":
            raise HdrioError(f"--align {mode}: {why}; give --align off")
        motion.too_small = why
        return stack, response, motion
    model = "euclidean" if mode == "auto" else mode
    if mode == "auto" and skip_warp:
        linear = linear_tables(response, stack.exposures)
        masks = usable_masks(stack.codes, stack.code_max, excluded,  # read once for all three
                             linear[0])
        # Stillness is checked from the bracket that sees most of the scene: from the
        # merge's reference (often a long bracket) the shortest ones share too few points.
        best = best_exposed_bracket(stack.codes, stack.code_max, masks=masks)
        motion.best_exposed = best
        still, refused = looks_still(stack.codes, linear, stack.code_max, best, masks,
                                     excluded)
        if still:
            reference = reference_bracket(stack.codes, stack.code_max, masks=masks)
            motion.alignment = Alignment(reference, np.repeat(np.eye(3)[None], stack.count, 0),
                                         model, (0.0,) * stack.count,
                                         tuple(sorted(refused.items())))
            return stack, response, motion
    motion.alignment, response = register(stack, response, model, solve, excluded)
    if mode != "auto" or motion.alignment.moved or not skip_warp:
        stack = align_stack(stack, motion.alignment, in_place=in_place)
        motion.warped = True
    return stack, response, motion


def deghost_step(stack: ExposureStack, response: CameraResponse, motion: Motion,
                 deghost_mode: str,
                 solve: Callable[[ExposureStack, np.ndarray], CameraResponse] | None,
                 noise: NoiseModel | None = None, excluded: np.ndarray | None = None,
                 clip: tuple | None = None) -> CameraResponse:
    """Per-bracket keep weights (``motion.keep``): uncovered borders of warped brackets
    and, with ``deghost_mode`` ``auto``, observations inconsistent with the reference.

    When motion is found and ``solve`` is given, the response is re-solved without the
    moving pixels and returned: the sampler draws from rare code values first, and a
    moving object's codes are rare (a bright object in one bracket bent the response
    enough to double the error inside it on the truth scene); again, up to
    :data:`RESOLVES` times in all, while the straighter curve finds more moving than
    was left out (:data:`GROWN`).

    ``noise``: the stack's noise model (:mod:`hdrio.radiometry.noise`), which the consistency
    test reads (:func:`hdrio.align.deghost.consistency_variance`); ``excluded``: ``(P, H,
    W)`` observations the merge leaves out (``--exclude-color``, ``--mask``); ``clip``: the
    merge's saturation policy in a stack that mixes its channels after the clip, whose
    observations dropped whole say nothing of motion (:func:`hdrio.align.deghost.deghost`;
    the re-solved response's test reads the same)."""
    if stack.count < 2 or (deghost_mode == "off" and not motion.warped):
        return response
    count, height, width, _ = stack.codes.shape
    # The bracket the others are tested against: the one that sees most of the scene (not
    # necessarily the one they were aligned to, which carries most of the merge).
    reference = (motion.best_exposed if motion.best_exposed is not None
                 else best_exposed_bracket(stack.codes, stack.code_max,
                                           linear=np.exp(response.log_inverse).T))
    cells = None
    if motion.warped:
        cells = np.stack([coverage(motion.alignment.transforms[j], height, width, CELL)
                          for j in range(count)])
        cells[motion.alignment.reference] = 1.0
        motion.uncovered = float(np.mean(cells.min(axis=0) < 1))
        refused = [j for j, _ in motion.alignment.refused]
        if refused:  # never merged unwarped where a registered bracket sees the scene
            registered = [j for j in range(count) if j not in refused]
            seen = seen_elsewhere(stack.codes, stack.code_max, registered, CELL)
            # ... but where it alone sees a highlight every registered bracket clipped,
            # it is: a sun that only the darkest frame reads (through an ND filter, or
            # the shortest of a ladder, too dark to register) was a neutral lower bound,
            # 390x too dark.
            only = {j: clipped_elsewhere(stack.codes, stack.code_max, registered, j, CELL)
                    for j in refused}
            for j in refused:
                cells[j] *= ~seen | only[j]
            motion.unregistered = (~seen & np.any(
                [seen_elsewhere(stack.codes, stack.code_max, [j], CELL) for j in refused],
                axis=0)) | np.any(list(only.values()), axis=0)
    if deghost_mode == "off":
        motion.keep = cells
        return response
    motion.deghosting = first = deghost(
        stack.codes, linear_tables(response, stack.exposures),
        consistency_variance(response, stack.exposures, noise), reference, cells,
        resampled=motion.warped, excluded=excluded, clip=clip)
    exclude = falls = None
    if solve is not None and first.fraction > 0:
        # Left out of the solve too, when the response's samples outside what was
        # found fall (:data:`FALLING_LEFT`): the pixels whose codes fall with exposure
        # (a small dark object in front of a window, which only the longest bracket
        # shows, next to a clipped channel everywhere and so never found: it bent the
        # curve by 0.07 at code 240 and the whole image's error was 2.9x the still
        # stack's; left out, 0.99x).
        exclude = _pixels(first.keep.min(axis=0) < 1, height, width)
        if falling_fraction(stack, response, exclude) >= FALLING_LEFT:
            falls = falling_pixels(stack.codes, stack.code_max)
            exclude |= falls
    elif solve is not None and falling_fraction(stack, response) >= FALLING_SAMPLES:
        # Nothing found, but the response's own samples say something moved: a mover
        # bent the curve, and the noise fit took the disagreement it left for noise (a
        # dark figure in every bracket of three, over a clipped background, 5 % of the
        # frame: the fitted relative noise 10x a still stack's, nothing deghosted, the
        # figure merged from three places as coloured speckle). Solved again without
        # the pixels whose codes fall with exposure, and tested again.
        falls = falling_pixels(stack.codes, stack.code_max)
        exclude = falls.copy()
    last = first  # the test before each re-solve
    for attempt in range(RESOLVES):
        if exclude is None:
            break
        try:
            # Warped brackets as register's re-solve has them: on the aligned sample, no
            # invented borders, no sharp edges, every bracket blurred alike (the stack
            # is in the reference's frame now).
            solved = (solve_on_sample(stack, replace(motion.alignment, transforms=np.repeat(
                np.eye(3)[None], count, axis=0)), solve, exclude, response) if motion.warped
                else solve(stack, exclude))
        except HdrioError:  # too little left to solve from: keep the response we have
            break
        # The first response and its noise fit saw the movers too (a dark object in
        # 5 % of a frame bent the curve by 0.9 stop and the fitted noise 200x):
        # tested again with both as the still scene gives them. Nothing moving then:
        # the first response stands (a still stack's merge is --deghost off's).
        noise = fit_noise(stack.codes, stack.exposures, solved, encoding=(
            "8-bit JPEG" if noise is not None and noise.common is not None else None),
            exclude=excluded)
        found = deghost(
            stack.codes, linear_tables(solved, stack.exposures),
            consistency_variance(solved, stack.exposures, noise), reference, cells,
            resampled=motion.warped, excluded=excluded, clip=clip)
        before = motion.deghosting.keep.min(axis=0) < 1
        # Solved again, it stands only if it finds no less (--align homography on the
        # canal: the third test found 0.43 % where the second had 0.76 %, and left a
        # seam across the flapping laundry).
        if found.fraction > 0 and (attempt == 0
                                   or found.fraction >= motion.deghosting.fraction):
            motion.deghosting, response = found, solved
        elif first.fraction > 0 and attempt == 0:
            motion.deghosting = found
        # Solved again while the straighter curve finds more moving than was left out
        # (five dark objects, one a bracket: 40 % dropped first, 56 % then, the curve
        # still bent by 0.13 stop at code 240).
        dropped = found.keep.min(axis=0) < 1
        if found.fraction <= GROWN * last.fraction or not np.any(dropped & ~before):
            break
        exclude = _pixels(dropped | before, height, width)
        if falls is not None:
            exclude |= falls
        last = found
    keep = motion.deghosting.keep
    motion.keep = keep if cells is not None or keep.min() < 1.0 else None  # nothing dropped
    return response
