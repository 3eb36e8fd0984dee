"""Aligning a stack: a reference bracket, each other bracket's warp to it, the warp applied.

:func:`estimate_alignment` measures (median threshold bitmaps for the coarse shift,
then Lucas-Kanade on linearised, exposure-normalised images); :func:`align_stack`
resamples the brackets that moved. ``--align`` chooses:

``auto`` (default)
    measure translation + rotation; warp only when some bracket moved by more than
    :data:`WITHIN` pixels (otherwise the warp is skipped, and reported so).
``off``
    neither measure nor warp.
``translation``, ``euclidean``, ``homography``
    measure with that model and warp.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

import numpy as np

from hdrio.align.correlation import NCC_PIXELS, masked_ncc_shift
from hdrio.align.highlight_shift import (
    MAX_SHIFT,
    channel_clip_regions,
    highlight_shift,
    refine_by_centroids,
)
from hdrio.align.lucaskanade import (
    MIN_POINTS,
    POINTS,
    corner_motion,
    refine_LucasKanade,
    rescale,
    residuals,
    strongest,
    strongest_usable,
    translation,
)
from hdrio.align.pyramid import (
    REGISTRABLE,
    BaseImage,
    base_blocks,
    base_factor,
    base_image,
    downsample,
    downsample_valid,
    levels_above,
)
from hdrio.align.resolve import solve_on_sample
from hdrio.align.ward2003 import align_Ward2003
from hdrio.align.warp import warp_codes
from hdrio.errors import HdrioError
from hdrio.parallel import map_on_threads
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.tables import estimate_tables
from hdrio.skips import well_exposed_codes
from hdrio.stack import ExposureStack

WITHIN = 0.1
"""``auto`` warps only when some bracket moves a corner by more than this (pixels)."""

RESOLVES = 3
"""Response re-solves at most in :func:`register`: each on the latest alignment, until
the alignment measured with it agrees with the one it was solved on
(:data:`RESOLVE_WITHIN`)."""

RESOLVE_WITHIN = 0.5
"""Pixels at the corners within which two alignments agree (:func:`register`): the
issue's bound for registration."""

REFINE_LEVELS = 4
"""Pyramid levels above the base that the refinement starts from (the bitmaps' shift is
within a base pixel; 4 levels absorb a rotation moving the corners by 16 base pixels)."""

SMOOTHING = 1.0

COARSE_TIE = 1.25
"""A shift is refused as an alias when, at the coarsest level, it fits worse than no
motion by more than this factor. (Smoothed that much, a true shift of a pixel or two
there fits about as well as none: 0.030 against 0.026 and 0.145 against 0.144 on
generated hand-held JPEG ladders, where a strict comparison refused their middle
brackets; an alias a period off fits clearly worse.)"""

COARSE_SHARE = 0.25
"""The share of the coarsest level's usable pixels, its strongest gradients, that the
alias test compares misfits on. (On all of them, the smooth sky of a hand-held 9 x 2 EV
ladder, 60 % of the points, where a shift of a pixel or two is a change of brightness,
decided the median: bracket 3 of ``hand_held(9, 5)``, measured 0.02 px from its true
warp, was refused, 0.021 against 0.012 unmoved; on its strongest quarter it fits
better than no motion.)"""

JUDGE_SHARE = 0.1
"""The share of the base image, its strongest gradients (at most
:data:`hdrio.align.lucaskanade.POINTS`), that a measured warp is judged on against no
motion."""

IMPROVEMENT = 0.8
"""A bracket's measured warp is kept only when its misfit is under this fraction of the
misfit of no motion (:func:`hdrio.align.lucaskanade.residuals`, on the same points)."""

POLISH_STEPS = (1.0, 0.5, 0.25, 0.125)
"""Base pixels: the steps :func:`_polished` tries, largest first."""
POLISH_REACH = 4.0
"""Base pixels: :func:`_polished` moves a warp by at most this in all."""

CLIP_AGREE = 1.0
"""Base pixels: a warp the edges cannot judge is taken when the shift of the highlights
its longer neighbour clipped, in one channel, puts the image's centre within this of it,
and nearer it than no motion (:func:`_register_pair`)."""

UNREFINED = 0.5
"""Base pixels: the precision of a highlight shift its centroids could not refine
(:func:`hdrio.align.highlight_shift.refine_by_centroids`: the matched masks' correlation
peak). A bracket registered by that shift alone, which moves it by less, is taken as not
moved: on still linear 16-bit ladders whose highlights touch the image's edge the
unrefined shift was 0.18-0.36 px, and those brackets were warped."""

CLEAR = 0.25
"""A warp whose misfit is under this fraction of no motion's is clearly right: no second
start is tried (:func:`_register_pair`; textured scenes measure 0.03-0.06 at 24 MP)."""

MTB_LEVELS = 6
"""Median-threshold-bitmap levels: shifts up to 63 base pixels (252 pixels at 24 MP)."""

MIN_USABLE = 0.005
"""A bracket is registered only when at least this fraction of the image is usable
(every channel well exposed: unclipped and above the noise, :data:`hdrio.skips.WELL_EXPOSED`)
in it and in the bracket it is registered to; otherwise it is left unwarped and the run
says so. (The truth harness's still GoldenGate/dorf0 stack at 250 px: its longest bracket
is 0.9 % usable, and a shift found there was 31 px of nothing.)"""

MIN_USABLE_PIXELS = 400
"""... and at least this many base pixels (a small image's 2 % is too few to register)."""


@dataclass(frozen=True)
class Alignment:
    """What :func:`estimate_alignment` found.

    Attributes
    ----------
    reference
        Index of the reference bracket (in the stack's exposure order).
    transforms
        ``(P, 3, 3)``: ``x_moving = W x_reference`` in full-resolution pixels (the
        reference's is the identity).
    model
        ``translation``, ``euclidean`` or ``homography``.
    motion
        Per bracket, the largest distance a corner of the image moves (pixels).
    """

    reference: int
    transforms: np.ndarray
    model: str
    motion: tuple[float, ...]
    refused: tuple[tuple[int, str], ...] = ()
    """``(bracket, why)`` for each bracket not registered (left unwarped): too little of
    it usable, or a shift the evidence does not support."""
    by_highlights: tuple[int, ...] = ()
    """Brackets registered by the highlights their longer neighbour clipped
    (:mod:`hdrio.align.highlight_shift`): too little of them usable where the neighbour
    is, a shift measured at the highlights (rotation the neighbour's)."""

    @property
    def moved(self) -> bool:
        """True when some bracket moves by more than :data:`WITHIN` pixels."""
        return max(self.motion) > WITHIN

    def describe(self, files: tuple[str, ...] | None = None) -> list[str]:
        """One line per bracket: shift (pixels), rotation (degrees), for the summary."""
        lines = []
        refused = dict(self.refused)
        for j, warp in enumerate(self.transforms):
            if j == self.reference:
                continue
            name = files[j] if files else f"bracket {j}"
            if j in refused:
                lines.append(f"{name}: not registered ({refused[j]}): merged unwarped only "
                             "where no registered bracket sees the scene (motion layer)")
                continue
            angle = math.degrees(math.atan2(warp[1, 0], warp[0, 0]))
            how = (", by the highlights its neighbour clipped" if j in self.by_highlights
                   else "")
            lines.append(f"{name}: shift {warp[0, 2]:+.2f}, {warp[1, 2]:+.2f} px, "
                         f"rotation {angle:+.3f} deg (corners move {self.motion[j]:.2f} px"
                         f"{how})")
        return lines


def _well_exposed_grids(codes: np.ndarray, code_max: int, samples: int,
                        masks: list[np.ndarray] | None, linear: np.ndarray | None = None):
    """Each bracket's well-exposed pixels (every channel within
    :data:`hdrio.skips.WELL_EXPOSED`, in light through ``linear`` when given:
    :func:`hdrio.skips.well_exposed_codes`) on a grid of about ``samples`` pixels, or
    ``masks`` of them already made, as a list of bool arrays."""
    if masks is not None:
        return masks
    height, width = codes.shape[1:3]
    step = max(1, int(math.sqrt(height * width / samples)))
    low, high = well_exposed_codes(code_max, linear=linear)
    grids = codes[:, step // 2::step, step // 2::step]
    return [np.all((grid >= low) & (grid <= high), axis=-1) for grid in grids]


def _nearest_the_middle(scores: list[int]) -> int:
    """The bracket of the highest score; the one nearest the middle on a tie."""
    middle = (len(scores) - 1) / 2.0
    return max(range(len(scores)), key=lambda j: (scores[j], -abs(j - middle)))


def best_exposed_bracket(codes: np.ndarray, code_max: int, samples: int = 65536,
                         masks: list[np.ndarray] | None = None,
                         linear: np.ndarray | None = None) -> int:
    """The best-exposed bracket of ``codes`` ``(P, H, W, C)``: the most pixels with every
    channel well exposed, on a grid of about ``samples`` pixels (or ``masks`` of them
    already made; ``linear``, ``(C, levels)``: the response's ``f^-1``, which sets the
    window of deep codes, :func:`hdrio.skips.well_exposed_codes`); the one nearest the
    middle on a tie. Deghosting tests every bracket against it
    (:mod:`hdrio.align.deghost`): it sees the most of the scene."""
    return _nearest_the_middle([int(np.count_nonzero(good)) for good in
                                _well_exposed_grids(codes, code_max, samples, masks, linear)])


def reference_bracket(codes: np.ndarray, code_max: int, samples: int = 65536,
                      masks: list[np.ndarray] | None = None,
                      linear: np.ndarray | None = None) -> int:
    """The bracket the others are aligned to: the one that carries most of the merge, the
    *longest* well-exposed bracket at the most pixels (grid, ``linear`` and ties as
    :func:`best_exposed_bracket`).

    The noise-optimal merge leans on the longest bracket not clipped at each pixel (the
    least noise there), so this is the bracket whose observations weigh most. Every other
    bracket is resampled onto it, and a resampled observation is off at sharp edges by a
    fraction of the edge (:mod:`hdrio.align.resampling`): the less of the merge's weight
    is resampled, the less of that error reaches it. On the truth stack (``python -m
    tests.align_truth``: GoldenGate, three brackets 2 EV apart) the best-exposed bracket
    is the shortest (well exposed at 97 % of the pixels, the middle one at 62 %); aligned
    to it, the merge's p99 error was 2.30x / 2.07x / 1.97x / 1.97x the still stack's
    (seeds 0-3), aligned to the middle one, which this rule chooses, 1.74x / 1.65x /
    1.77x / 1.51x."""
    scores = [0] * codes.shape[0]
    longer = None  # pixels some longer bracket is well exposed at
    grids = _well_exposed_grids(codes, code_max, samples, masks, linear)
    for j in reversed(range(len(grids))):
        good = grids[j]
        scores[j] = int(np.count_nonzero(good if longer is None else good & ~longer))
        longer = good.copy() if longer is None else longer | good
    return _nearest_the_middle(scores)


def _pyramid(base: BaseImage, levels: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(log radiance, valid)`` from the base up. Each level is smoothed by a Gaussian of
    :data:`SMOOTHING` pixels for the refinement: bilinear sampling of a sharp image
    biases Lucas-Kanade towards whole pixels (0.08 px on the truth stacks without)."""
    import scipy.ndimage
    out = [(base.log, base.valid)]
    for _ in range(levels):
        image, valid = out[-1]
        out.append((downsample(image), downsample_valid(valid)))
    return [(scipy.ndimage.gaussian_filter(image, SMOOTHING), valid) for image, valid in out]


class _Pyramids:
    """The brackets' pyramids (:func:`_pyramid`), each built when a pair first needs it
    and dropped after the last pair :meth:`expect` counted for it (a bracket's pyramid is
    read by its pairs with both neighbours, on different threads): at 24 MP, building all
    seven first held 16-36 MB more at the peak. A pyramid asked for again later is built
    again."""

    def __init__(self, bases: list[BaseImage], levels: int) -> None:
        self._bases, self._levels = bases, levels
        self._lock = threading.Lock()
        self._built: dict[int, list] = {}  # bracket -> [its lock, its pyramid or None]
        self._uses: dict[int, int] = {}

    def expect(self, pairs: list[tuple[int, int]]) -> None:
        """Count the pairs that will read each pyramid."""
        for pair in pairs:
            for j in pair:
                self._uses[j] = self._uses.get(j, 0) + 1

    @contextlib.contextmanager
    def held(self, j: int) -> Iterator[list[tuple[np.ndarray, np.ndarray]]]:
        """Bracket ``j``'s pyramid, built by the first to ask; given back at the end."""
        with self._lock:
            entry = self._built.setdefault(j, [threading.Lock(), None])
        with entry[0]:
            if entry[1] is None:
                entry[1] = _pyramid(self._bases[j], self._levels)
        try:
            yield entry[1]
        finally:
            with self._lock:
                self._uses[j] = self._uses.get(j, 0) - 1
                if self._uses[j] <= 0 and self._built.get(j) is entry:
                    del self._built[j]


def linear_tables(response: CameraResponse, exposures: np.ndarray) -> np.ndarray:
    """``(P, C, levels)`` float64: ``f^-1(z) / dt_j``, relative radiance per code."""
    return np.ascontiguousarray(
        estimate_tables(response, exposures, "linear").transpose(0, 2, 1))


def estimate_alignment(stack: ExposureStack, response: CameraResponse,
                       model: str = "euclidean", excluded: np.ndarray | None = None
                       ) -> Alignment:
    """Measure every bracket's warp to the reference bracket.

    The codes are read once per bracket (to build its base image); everything else
    works on the base and its pyramid (:mod:`hdrio.align.pyramid`). ``excluded``: ``(P,
    H, W)`` observations the merge leaves out (``--mask``, ``--exclude-color``), each
    in its bracket's own frame; no base pixel that holds one is read, and a pair's
    highlights are matched outside those of either bracket.
    """
    count, height, width, _ = stack.codes.shape
    factor = base_factor(height, width)
    linear = linear_tables(response, stack.exposures)
    bases = [base_image(stack.codes[j], linear[j], stack.code_max, factor)
             for j in range(count)]
    held = [None if excluded is None or not excluded[j].any()
            else base_blocks(excluded[j], factor) for j in range(count)]
    for base, out in zip(bases, held):
        if out is not None:
            base.valid &= ~out

    def kept(k: int, j: int, region: np.ndarray) -> np.ndarray:
        """``region`` outside either bracket's excluded base pixels."""
        for out in (held[k], held[j]):
            if out is not None:
                region = region & ~out
        return region
    reference = reference_bracket(stack.codes, stack.code_max, linear=linear[0])
    top = well_exposed_codes(stack.code_max, REGISTRABLE)[1]  # a base's highest valid code
    levels = min(REFINE_LEVELS, levels_above(*bases[0].log.shape))
    transforms = np.repeat(np.eye(3)[None], count, axis=0)  # base pixels, then full
    refused: dict[int, str] = {}
    by_highlights: list[int] = []
    pyramids = _Pyramids(bases, levels)

    def pair(k: int, j: int) -> tuple[np.ndarray, str | None, bool]:
        """``j``'s warp to ``k``, why it is refused (or ``None``), and whether it was
        measured on the highlights ``k`` clipped."""
        why = unusable(bases[k].valid, bases[j].valid)
        if why is not None and j < k:  # a shorter one: by the highlights k clipped
            level = float(np.log(linear[k][:, top].sum()))
            clipped = kept(k, j, bases[k].grey >= top)
            step = highlight_shift(clipped, kept(k, j, bases[j].log >= level))
            if step is None:
                return np.eye(3), why, False
            refined = refine_by_centroids(step, bases[k].log, bases[k].valid, clipped,
                                          bases[j].log, bases[j].valid, level)
            if refined is step and np.hypot(step[0, 2], step[1, 2]) < UNREFINED:
                return np.eye(3), None, True  # within the shift's own precision
            return refined, None, True
        if why is not None:
            return np.eye(3), why, False
        with pyramids.held(k) as pyramid_k, pyramids.held(j) as pyramid_j:
            return (*_register_pair(pyramid_k, pyramid_j, bases[k], bases[j], model,
                                    stack.code_max,
                                    (lambda: clip_shift(k, j)) if j < k else None), False)

    def clip_shift(k: int, j: int) -> np.ndarray | None:
        """The shorter ``j``'s shift to ``k`` matched on the highlights ``k`` clipped in
        one channel (:func:`hdrio.align.highlight_shift.channel_clip_regions`)."""
        regions = channel_clip_regions(stack.codes[k], stack.codes[j], top, factor)
        return None if regions is None else highlight_shift(
            *(kept(k, j, region) for region in regions))

    # Each bracket is aligned to its nearest registered neighbour towards the reference
    # (the pair shares the most well-exposed pixels), and the warps composed. Every
    # bracket's pair with its next neighbour inwards is measured at once, on every
    # thread (NumPy and SciPy release the GIL for most of a pair's work); a bracket
    # beyond one that could not be registered is measured again against the last one
    # that was.
    inwards = [(j + 1 if j < reference else j - 1, j) for j in range(count)
               if j != reference and j not in refused]
    pyramids.expect(inwards)
    measured = dict(zip(inwards, map_on_threads(lambda kj: pair(*kj), inwards)))
    for side in (range(reference - 1, -1, -1), range(reference + 1, count)):
        k = reference
        for j in side:
            if j in refused:
                continue
            step, why, highlights = measured[(k, j)] if (k, j) in measured else pair(k, j)
            if why is not None:  # left unwarped; the next bracket out pairs with k
                refused[j] = why
                continue
            if highlights:
                by_highlights.append(j)
            transforms[j] = step @ transforms[k]
            k = j
    motion = [0.0] * count
    for j in range(count):
        transforms[j] = rescale(transforms[j], factor) if factor > 1 else transforms[j]
        motion[j] = corner_motion(transforms[j], height, width)
    return Alignment(reference, transforms, model, tuple(motion),
                     tuple(sorted(refused.items())), tuple(sorted(by_highlights)))


def unusable(valid_k: np.ndarray, valid_j: np.ndarray, scale: float = 1.0) -> str | None:
    """Why two brackets (their base images' ``valid`` masks, or a sample of them each
    pixel of which stands for ``scale`` base pixels) cannot be registered to each other,
    or ``None``: less than :data:`MIN_USABLE` of the image (or :data:`MIN_USABLE_PIXELS`
    base pixels) is usable in both."""
    common = int(np.count_nonzero(valid_k & valid_j))
    if common < max(MIN_USABLE * valid_k.size, MIN_USABLE_PIXELS / scale):
        return (f"only {100.0 * common / valid_k.size:.1f} % of it is unclipped and above "
                f"the noise where its neighbour is, {100 * MIN_USABLE:g} % needed")
    return None


TEXTURE = 0.02
"""A shift is measurable only when, at the points it is measured on, the gradients along
x and along y and a constant (the exposure offset) are not nearly collinear: the smallest
eigenvalue of their normalised Gram matrix is above this. (An exponential ramp, log-linear
along x, has the same x gradient everywhere: any x shift fits as well as an offset, and
on 48x64 pixels one 2.8 px off fitted the noise 20 % better than none.)"""


def _textured(image: np.ndarray, index: np.ndarray) -> bool:
    """Whether ``image``'s gradients at the flat ``index`` pin a translation down
    (:data:`TEXTURE`)."""
    if index.size < 3:
        return False
    gy, gx = np.gradient(image)
    columns = np.stack([gx.reshape(-1)[index], gy.reshape(-1)[index],
                        np.ones(index.size)], axis=1).astype(np.float64)
    norms = np.linalg.norm(columns, axis=0)
    if np.any(norms == 0):
        return False
    gram = (columns / norms).T @ (columns / norms)
    return float(np.linalg.eigvalsh(gram)[0]) > TEXTURE


def _register_pair(pyramid_k, pyramid_j, base_k: BaseImage, base_j: BaseImage,
                   model: str, code_max: int,
                   clip_shift: Callable[[], np.ndarray | None] | None = None
                   ) -> tuple[np.ndarray, str | None]:
    """Bracket ``j``'s warp to ``k`` on the base grid, judged by its evidence
    (:func:`_judged`): ``(warp, None)``, the identity when the warp fits no better than
    no motion, or ``(identity, why)`` when it cannot be trusted.

    Lucas-Kanade refines the median-threshold bitmaps' shift; where that warp is not
    clearly right (:data:`CLEAR`) it refines a second start too, the shift that
    correlates the two brackets' log radiance best where both are usable
    (:func:`hdrio.align.correlation.masked_ncc_shift`), and the warp that fits better on
    the same points is judged. Either start alone fails somewhere: a bracket clipped
    over most of the frame thresholds its bitmap at the clip (the second longest of a
    hand-held 7 x 2 EV ladder with a sky, 98 % of it clipped: the bitmaps put it 15 px
    off, its few usable pixels within one), and from a guess far off Lucas-Kanade does
    not reach a shift of 9 px.

    For a shorter ``j``, ``clip_shift`` gives a third start: the shift of the highlights
    ``k`` clipped in the channel it clips least (a warm interior's long brackets, red
    clipped nearly everywhere: there the bitmaps sat in the clip and the correlation
    found nothing). That shift is a candidate itself too, and where the edges cannot
    judge the best warp (too few points in common, or no better than no motion) it is
    taken when the shift agrees with it (:data:`CLIP_AGREE`). The best warp of several
    starts is polished on the judge's misfit before it is judged (:func:`_polished`)."""
    dx, dy = align_Ward2003(base_k.grey, base_j.grey, MTB_LEVELS, code_max)
    step = refine_LucasKanade(pyramid_k, pyramid_j, translation(dx, dy), model)
    warp, why, ratio = _judged(pyramid_k, pyramid_j, step)
    shape = pyramid_k[0][0].shape
    level = next((k for k, (image, _) in enumerate(pyramid_k) if image.size <= NCC_PIXELS),
                 len(pyramid_k) - 1)
    if why is None and (ratio <= CLEAR or corner_motion(step, *shape) <= 2.0**level):
        # Clearly right; or no motion, the refinement within a pixel of the level the
        # correlation reads in whole pixels (it cannot start anywhere nearer).
        return warp, why
    guess = masked_ncc_shift(*pyramid_k[level], *pyramid_j[level], MAX_SHIFT >> level)
    starts = [step]
    if guess is not None:
        guess = rescale(guess, 2.0**level)
        if corner_motion(np.linalg.inv(guess) @ step, *shape) > 2.0**level:
            starts.append(refine_LucasKanade(pyramid_k, pyramid_j, guess, model))
    shift = clip_shift() if clip_shift is not None else None
    if shift is not None and all(corner_motion(np.linalg.inv(shift) @ start, *shape)
                                 > 2.0**level for start in starts):
        # The shift itself too, not only where Lucas-Kanade takes it from there: on a
        # dark bracket (StillLife's 7-bracket ladder, the second shortest) it was
        # within 0.2 px, and the refinement walked 1-10 px off, fitting worse.
        starts += [shift, refine_LucasKanade(pyramid_k, pyramid_j, shift, model)]
    best = starts[0]
    for other in starts[1:]:
        best = _better(pyramid_k, pyramid_j, best, other)
    measured = best is not shift  # by the edges, not the highlights' shift alone
    polished = _polished(pyramid_k, pyramid_j, best)
    if len(starts) > 1 or polished is not best:  # else the first start, judged above
        best = polished
        warp, why, _ = _judged(pyramid_k, pyramid_j, best)
    if (shift is not None and measured and (why is not None or warp is not best)
            and _agree_at_centre(best, shift, shape)):
        # The edges could not tell (too few in common to judge, or no better than no
        # motion), and the highlights the longer bracket clipped put the shorter one
        # where the edges do: two measures that share nothing agree.
        return best, None
    return warp, why


def _polished(pyramid_k, pyramid_j, warp: np.ndarray) -> np.ndarray:
    """``warp`` moved by whole steps of :data:`POLISH_STEPS` base pixels along x or y while
    that lowers its misfit on the judge's points (:func:`_judging_points`, the robust
    misfit of :func:`hdrio.align.lucaskanade.residuals`), each step size until none does,
    by at most :data:`POLISH_REACH` in all; ``warp`` itself when nothing lowers it.

    For a pair the first start did not settle clearly: Lucas-Kanade's least squares,
    with its one exposure offset, can rest where the judge's misfit is not least. On the
    dark second shortest bracket of StillLife's 7 x 2 EV ladder it walked 1.1-1.8 px
    from the true warp when started there, which fits better. The rotation is left as it
    is: polished the same way, the misfit barely changes with it, and the corners went
    further off (seed 3: 1.65 px)."""
    fine_k, fine_j = pyramid_k[0], pyramid_j[0]
    points = _judging_points(fine_k)
    best, least = warp, residuals(*fine_k, *fine_j, [warp], index=points)[0]
    if not np.isfinite(least):
        return warp
    moved = np.zeros(2)
    for step in POLISH_STEPS:
        improved = True
        while improved:
            moves = [move for move in ((step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step))
                     if np.hypot(*(moved + move)) <= POLISH_REACH]
            if not moves:
                break
            misfits = residuals(*fine_k, *fine_j, [translation(*move) @ best
                                                   for move in moves], index=points)
            k = int(np.argmin(misfits))
            improved = misfits[k] < least
            if improved:
                best, least = translation(*moves[k]) @ best, misfits[k]
                moved += moves[k]
    return best


def _agree_at_centre(first: np.ndarray, second: np.ndarray, shape) -> bool:
    """Whether two warps move the image's centre to within :data:`CLIP_AGREE` base pixels
    of each other, the first by more than :data:`WITHIN` (it is not no motion), and the
    second nearer the first than no motion: a second that puts the centre where it was
    agrees with no motion rather than with the first. (On a still phone night stack,
    the edges of its two darkest frames, noise alone, preferred a warp moving the centre
    1.3 px, which fitted no better than none; the lamp's shift, 0.1 px, was within
    :data:`CLIP_AGREE` of it, and both frames were warped 1.6 px.)"""
    height, width = shape
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0, 1.0])
    a, b = first @ centre, second @ centre
    a, b = a[:2] / a[2], b[:2] / b[2]
    moved = np.hypot(*(a - centre[:2]))
    apart = np.hypot(*(a - b))
    return moved > WITHIN and apart <= CLIP_AGREE and apart < np.hypot(*(b - centre[:2]))


def _better(pyramid_k, pyramid_j, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Whichever of two warps of ``j`` to ``k`` fits better on the base level: both over
    the same points, or where they keep too few in common, each over its own."""
    fine_k, fine_j = pyramid_k[0], pyramid_j[0]
    misfits = residuals(*fine_k, *fine_j, [first, second], index=_judging_points(fine_k))
    if not np.all(np.isfinite(misfits)):
        misfits = [residuals(*fine_k, *fine_j, [warp], index=strongest_usable(
            *fine_k, *fine_j, warp))[0] for warp in (first, second)]
    return second if misfits[1] < misfits[0] else first


def _judging_points(fine: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The base level's strongest gradients a warp is judged on (:data:`JUDGE_SHARE`)."""
    return strongest(*fine, max(MIN_POINTS, min(POINTS, int(JUDGE_SHARE * fine[1].size))))


def _judged(pyramid_k, pyramid_j, step: np.ndarray) -> tuple[np.ndarray, str | None, float]:
    """``step`` (``j``'s measured warp to ``k``, base grid) judged by its evidence:
    ``(step, None)``; the identity and ``None`` when it fits no better than no motion;
    or the identity and why it cannot be trusted. Third, the misfit of ``step`` over no
    motion's (``inf`` where not measured)."""
    still = np.eye(3)
    fine_k, fine_j = pyramid_k[0], pyramid_j[0]
    too_few = "too few well-exposed edges in common to judge a shift"
    points = _judging_points(fine_k)
    moved, unmoved = residuals(*fine_k, *fine_j, [step, still], index=points)
    if not np.isfinite(moved + unmoved) and corner_motion(step, *fine_k[0].shape) <= WITHIN:
        # A warp that moves nothing keeps the points no motion keeps: too few of the
        # strongest tenth are usable in j (a filtered frame that sees only the sun), so
        # it is judged on more of them.
        points = strongest(*fine_k)
        moved, unmoved = residuals(*fine_k, *fine_j, [step, still], index=points)
    apart = not (np.isfinite(moved) and np.isfinite(unmoved))
    if apart:
        # The two warps keep apart regions of j (a bracket usable in a few patches,
        # moved by more than their size): each misfit over the points its warp keeps.
        # No motion keeps the easier ones (see residuals): a shift that fits clearly
        # better all the same is real, and one that does not is not judged.
        points = strongest_usable(*fine_k, *fine_j, step)
        moved = residuals(*fine_k, *fine_j, [step], index=points)[0]
        unmoved = residuals(*fine_k, *fine_j, [still])[0]
    if corner_motion(step, *fine_k[0].shape) > 0 and not _textured(fine_k[0], points):
        return still, ("a smooth gradient: a shift along it is a change of brightness, "
                       "nothing to register"), np.inf
    if not (np.isfinite(moved) and np.isfinite(unmoved)):
        return still, too_few, np.inf
    # Keep the estimate only if it fits clearly better than no motion at all: where
    # the scene gives no purchase (a smooth gradient, clipping that moves the bitmaps'
    # medians) any shift fits as well, and the camera most likely held still.
    ratio = moved / unmoved if unmoved > 0 else np.inf
    if moved > IMPROVEMENT * unmoved:
        return (still, too_few, ratio) if apart else (still, None, ratio)
    # A real shift fits better at every level; one that fits the fine level only (an
    # alias, a repeated texture a period off) does not at the coarsest.
    top = len(pyramid_k) - 1
    coarse = rescale(step, 0.5**top)
    if top > 0 and corner_motion(coarse, *pyramid_k[top][0].shape) > 1.0:
        image, valid = pyramid_k[top]
        points = strongest(image, valid, max(MIN_POINTS, int(
            COARSE_SHARE * np.count_nonzero(valid))))
        moved_c, unmoved_c = residuals(*pyramid_k[top], *pyramid_j[top], [coarse, still],
                                       index=points)
        if not moved_c <= COARSE_TIE * unmoved_c:
            return still, (f"the shift fits the fine level only (misfit {moved_c:.3f} "
                           f"against {unmoved_c:.3f} unmoved at the coarsest)"), ratio
    return step, None, ratio


def align_stack(stack: ExposureStack, alignment: Alignment,
                in_place: bool = False) -> ExposureStack:
    """``stack`` with every bracket but the reference resampled onto the reference
    (:mod:`hdrio.align.warp`).

    ``in_place`` overwrites ``stack.codes`` a bracket at a time through one bracket's
    buffer (for a caller that owns a freshly read stack: no second copy of the codes);
    otherwise the codes are copied first and ``stack`` is left as it was.
    """
    codes = stack.codes if in_place else np.empty_like(stack.codes)
    buffer = np.empty(codes.shape[1:], codes.dtype) if in_place else None
    for j in range(stack.count):
        if j == alignment.reference or alignment.motion[j] == 0.0:
            if not in_place:
                codes[j] = stack.codes[j]
            continue
        if in_place:
            warp_codes(codes[j], alignment.transforms[j], stack.code_max, buffer)
            codes[j] = buffer
        else:  # straight into the copy: no second pass over the bracket
            warp_codes(stack.codes[j], alignment.transforms[j], stack.code_max, codes[j])
    return replace(stack, codes=codes)


def align_masks(masks: np.ndarray, alignment: Alignment) -> np.ndarray:
    """Per-bracket exclusion masks ``(P, H, W)`` bool, each in its own bracket's frame,
    moved onto the reference as :func:`align_stack` moves the codes: the nearest pixel,
    grown by 2 pixels, the reach of the cubic interpolation (a warped code within it
    took some of an excluded one)."""
    import scipy.ndimage
    out = masks.copy()
    for j in range(masks.shape[0]):
        if j == alignment.reference or alignment.motion[j] == 0.0:
            continue
        mask = np.ascontiguousarray(masks[j, ..., None], dtype=np.uint8)
        warped = warp_codes(mask, alignment.transforms[j], 1, interpolate=False)[..., 0]
        out[j] = scipy.ndimage.maximum_filter(warped, size=5) > 0
    return out


def register(stack: ExposureStack, response: CameraResponse, model: str,
             solve: Callable[[ExposureStack, np.ndarray], CameraResponse] | None = None,
             excluded: np.ndarray | None = None) -> tuple[Alignment, CameraResponse]:
    """Measure the alignment; when brackets moved and ``solve`` is given, re-solve the
    response on an aligned sample of the stack (a response solved on moving brackets
    mixes scene points at edges) and measure again with it, until the alignment agrees
    with the one the response was solved on (:data:`RESOLVES`, :data:`RESOLVE_WITHIN`).
    Returns the alignment and the response to merge with.

    ``solve(stack, exclude)`` solves a response, ``exclude`` an ``(H, W)`` mask of pixels
    not to sample. On the truth stacks the second pass takes the corner error from
    0.1-0.4 px to under 0.09 px. It measures afresh, bitmaps and coarse levels too: the
    first response can be bent enough for the first pass to put a bracket 5-10 px off
    (the short brackets of the 9 x 2 EV hand-held ladders of ``tests/hard_cases.py``),
    and refining only the base level from there left bracket 2 of ``hand_held(9, 1)``
    4.4 px off (0.03 px measured afresh). A response solved on such a first pass is bent
    too (``hand_held(7, 19)``: brackets 0 and 1 9.7 px off, the curve up to 0.018 r.m.s.
    from the truth against the still stack's 0.007, the merge's median error 1.70x the
    still stack's), so it is solved again on the second pass's alignment (1.22x).

    ``excluded``: ``(P, H, W)`` observations the merge leaves out, each in its bracket's
    own frame (:func:`estimate_alignment`); the re-solve leaves out every pixel any
    bracket excludes, as the response solve before alignment does.

    Where the passes end with nothing moved, ``response`` (solved on the brackets as
    read) is returned, not a re-solve on the sample: the brackets are merged as read. A
    still JPEG ladder (Desk through DoRF curve 0, ``python -m benchmarks.motion_still``)
    had its longest bracket put 0.53 px off by the first pass, none by the second and
    third, and was merged with the third's response, solved on the blurred sample
    without sharp edges: 5 % off its ``--align off`` merge at the median."""
    first = response
    alignment = estimate_alignment(stack, response, model, excluded)
    if solve is None or not alignment.moved:
        return alignment, response
    exclude = None if excluded is None else excluded.any(axis=0)
    for _ in range(RESOLVES):
        try:
            solved = solve_on_sample(stack, alignment, solve, exclude, response)
        except HdrioError:  # too little left to solve from: keep the response before
            break
        again = estimate_alignment(stack, solved, model, excluded)
        response, settled = solved, _agree(again, alignment, height=stack.shape[0],
                                           width=stack.shape[1])
        alignment = again
        if settled:
            break
    return alignment, response if alignment.moved else first


def _agree(first: Alignment, second: Alignment, height: int, width: int) -> bool:
    """Whether two alignments register the same brackets, each within
    :data:`RESOLVE_WITHIN` pixels of the other at the corners."""
    if {j for j, _ in first.refused} != {j for j, _ in second.refused}:
        return False
    return all(corner_motion(np.linalg.inv(a) @ b, height, width) <= RESOLVE_WITHIN
               for a, b in zip(first.transforms, second.transforms))

