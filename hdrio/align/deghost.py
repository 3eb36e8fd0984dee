"""Deghosting: one consistent snapshot of what moved, as one bracket saw it.

Every bracket is tested against the reference bracket, per cell of :data:`CELL` pixels
(:mod:`hdrio.align.consistency`: the mean capped ``d^2`` of its samples; noise averages
out, a moving object does not); a cell is inconsistent when that mean is above
:data:`THRESHOLD` (raised for a bracket whose still cells disagree more than the noise
model says). The inconsistent cells, grown by one cell, make the *moving regions*; each
region keeps the view of one bracket, its *source* (after Gallo et al. 2009 and Granados
et al. 2013): the reference, or where the reference is clipped over most of the region,
the bracket the most others agree with there (a moving object is at a different place
in each bracket: at any one place, the most brackets show what is behind it). In a
region only the brackets consistent with its source are merged; two views of a mover are
never blended, and a mover appears at most once. Outside the regions nothing is
dropped. Drops are grown by one cell and feathered by a Gaussian of one cell, so the
keep weight goes from 0 to 1 over a few cells of the still scene around a region and no
seam shows; the merge takes per-bracket weights bilinearly interpolated between cell
centres (:func:`hdrio.merge.masked.remerge_masked`). A cell a warped bracket does not
fully cover gets weight 0 for that bracket (:func:`hdrio.align.warp.coverage`).

A quick look first (:data:`COARSE`): cells that many times wider, samples that many
times sparser; only the coarse cells where a few samples disagree, and their
neighbours, are tested finely: on a still stack none is.

References
----------
Gallo, O., Gelfand, N., Chen, W.-C., Tico, M., & Pulli, K. (2009). Artifact-free high
dynamic range imaging. IEEE ICCP 2009.

Granados, M., Kim, K. I., Tompkin, J., & Theobalt, C. (2013). Automatic noise modeling
for ghost-free HDR reconstruction. ACM Transactions on Graphics 32(6), 201.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hdrio.align.comparametric import comparametric_correction, consistency_variance
from hdrio.align.consistency import TEST_BANDS, Tables, cell_disagreement, test_tables
from hdrio.radiometry.cliptest import untested

__all__ = ["CELL", "TEST_BANDS", "Deghosting", "comparametric_correction",
           "consistency_variance", "deghost"]

CELL = 8
"""Side of a test cell, pixels."""
STRIDE = 2
"""Pixels tested each way within a cell (every second: a quarter of the pixels)."""
THRESHOLD = 20.0
"""A cell is inconsistent when the mean of its samples' capped ``d^2`` exceeds this
(still stacks: cell means 0.5-2.2 at the median, at most 16 on five truth scenes with
the interim noise model; a 25 % disagreement alone gives about 35)."""
SCALED_MAX = 60.0
"""The most the threshold is raised for a bracket whose still cells disagree more than
the noise model says (see :func:`deghost`)."""
MIN_SAMPLES = 8
"""Cells with fewer usable samples of a bracket are not judged (kept)."""
COARSE = 4
"""The quick look's samples are at least this many times sparser than the fine test's,
its cells as many times wider (the same count of samples a cell)."""
QUICK_SAMPLES = 100_000
"""... and sparser still on large images: about this many samples a bracket."""
QUICK = 2.5
"""A coarse cell is looked at finely when its mean capped ``d^2`` is above this (times
the bracket's scale): a sample of its sixteen far out, or a few clearly off. (At 5, an
object 17 px across, 0.6 % of a 300 x 200 frame, half in a 32-px coarse cell, gave 4.5
and was kept as its bracket saw it, a second copy of it.)"""
FAR = 0.25
"""... and when more than this fraction of its samples are off the reference by more than
:data:`hdrio.align.consistency.EFFECT` (a moving object is off by a factor; film's
halation and a scan's misregistration around Memorial's lamps and ornaments made cells
many sigmas off by 10-40 %, and 29 % of that still stack was flagged)."""
MIN_CELLS = 2
"""A moving region holds at least this many flagged cells side by side (a cell is
:data:`CELL` pixels: the issue's small movers cover four or more)."""
CLIPPED_SOURCE = 0.5
"""A bracket with some channel saturated at more than this fraction of a region's samples
is not that region's source (:func:`_source`)."""


@dataclass
class Deghosting:
    """Per-bracket keep weights on a grid of cells.

    Attributes
    ----------
    keep
        ``(P, rows, cols)`` float32 in [0, 1], cell centres at ``(i + 0.5) * cell``.
    cell
        Cell side, pixels.
    reference
        The reference bracket.
    fraction
        Fraction of the image's pixels where some bracket was dropped for motion
        (weight below 1; borders a warp does not cover are not counted).
    sources
        ``(rows, cols)`` int8: the bracket whose view each moving region keeps, -1 where
        nothing moved (``None`` when nothing did anywhere).
    """

    keep: np.ndarray
    cell: int
    reference: int
    fraction: float
    sources: np.ndarray | None = None

    def motion_mask(self, height: int, width: int) -> np.ndarray:
        """``(H, W)`` float32: ``1 - min_j keep_j`` at full resolution (the EXR layer)."""
        import scipy.ndimage
        low = 1.0 - self.keep.min(axis=0)
        zoom = scipy.ndimage.zoom(low, self.cell, order=1, grid_mode=True,
                                  mode="nearest")
        out = np.zeros((height, width), np.float32)
        h, w = min(height, zoom.shape[0]), min(width, zoom.shape[1])
        out[:h, :w] = zoom[:h, :w]
        return np.clip(out, 0.0, 1.0)


def _fine_cells(suspect: np.ndarray, rows: int, cols: int, cell: int, size: int
                ) -> np.ndarray:
    """``(rows, cols)``: fine cells touching a ``suspect`` coarse cell of ``size`` px."""
    first_r, last_r = (np.minimum((np.arange(rows) * cell + k) // size,
                                  suspect.shape[0] - 1) for k in (0, cell - 1))
    first_c, last_c = (np.minimum((np.arange(cols) * cell + k) // size,
                                  suspect.shape[1] - 1) for k in (0, cell - 1))
    return (suspect[first_r][:, first_c] | suspect[last_r][:, last_c]
            | suspect[first_r][:, last_c] | suspect[last_r][:, first_c])


def _excluded_cells(excluded: np.ndarray, cell: int, rows: int, cols: int) -> np.ndarray:
    """``(P, rows, cols)``: cells holding an excluded observation of each bracket."""
    count, height, width = excluded.shape
    padded = np.zeros((count, rows * cell, cols * cell), bool)
    padded[:, :height, :width] = excluded
    return padded.reshape(count, rows, cell, cols, cell).any(axis=(2, 4))


@dataclass
class _Candidates:
    """What :func:`_source` reads of the moving regions: each bracket's test against
    the others over all the moving cells, computed once for all regions when first
    needed (a cell's tallies depend on its own pixels only, so each region reads its
    cells of the same arrays; a test per region and bracket took 24 of 30 s on a still
    9 x 24 MP JPEG stack with 209 small regions), and per region, how saturated and how
    noisy each bracket's view of it is."""

    codes: np.ndarray
    tables: Tables
    clip: tuple
    moving: np.ndarray
    cell: int
    resampled: bool
    tests: dict = field(default_factory=dict)

    def _samples(self, bracket: int, box: tuple[slice, slice], region: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """``bracket``'s codes at the test's samples (every :data:`STRIDE`-th pixel) of
        the cells within ``box``, and which of them are in ``region``'s cells."""
        half, cell = STRIDE // 2, self.cell
        rows, cols = box
        view = self.codes[bracket, rows.start * cell + half:rows.stop * cell:STRIDE,
                          cols.start * cell + half:cols.stop * cell:STRIDE]
        per = cell // STRIDE
        inside = np.repeat(np.repeat(region, per, axis=0), per, axis=1)
        return view, inside[:view.shape[0], :view.shape[1]]

    def clipped_fraction(self, bracket: int, box: tuple[slice, slice],
                         region: np.ndarray) -> float:
        """The fraction of ``region``'s samples (its cells within ``box``) where
        ``bracket`` has some channel saturated (above ``Z_max - 1``). Read from the
        region's box alone: over the whole image, for every bracket, it was half of
        :func:`_source`'s time on a 6 MP stack with one small region."""
        view, inside = self._samples(bracket, box, region)
        high = int(self.tables.variance.shape[2]) - 2
        largest = view[..., 0]
        for c in range(1, view.shape[-1]):  # by channel: faster than max(axis=-1)
            largest = np.maximum(largest, view[..., c])
        values = (largest > high)[inside]
        return float(np.mean(values)) if values.size else 0.0

    def noise(self, bracket: int, box: tuple[slice, slice], region: np.ndarray) -> float:
        """How noisy ``bracket``'s view of ``region`` (its cells within ``box``) is: the
        median, over the region's samples, of its estimates' relative variance (the mean
        over channels of ``variance / estimate^2``; ``inf`` where a channel says
        nothing, clipped or black)."""
        view, inside = self._samples(bracket, box, region)
        with np.errstate(divide="ignore", invalid="ignore"):
            relative = (self.tables.variance[bracket]
                        / np.square(self.tables.estimates[bracket]))
        relative[~np.isfinite(relative)] = np.inf
        total = np.zeros(view.shape[:2])
        for c in range(view.shape[2]):
            total += relative[c][view[..., c]]
        values = total[inside]
        return float(np.median(values)) if values.size else np.inf

    def test(self, bracket: int):
        """:func:`cell_disagreement` against ``bracket`` over the moving cells."""
        if bracket not in self.tests:
            self.tests[bracket] = cell_disagreement(self.codes, self.tables, self.clip,
                                                    bracket, self.cell, STRIDE, self.moving,
                                                    self.resampled)
        return self.tests[bracket]


def _source(candidates: _Candidates, reference: int, box: tuple[slice, slice],
            region: np.ndarray, flagged: np.ndarray, judged: np.ndarray,
            limits: np.ndarray) -> tuple[int, np.ndarray]:
    """The bracket whose view ``region`` keeps, and ``(P, rows, cols)`` the cells where
    each bracket disagrees with it (``flagged``: with the reference; ``judged``: cells
    with enough samples to tell), all within the region's bounding ``box`` of cells.

    Agreement is the fraction of the other brackets' judged moving cells (the region's
    cells where some bracket was found moving) that do not disagree with a view. The
    reference's view is kept when no other view has more agreement and it is not
    saturated at most of the region's samples (:data:`CLIPPED_SOURCE`). Otherwise the
    least noisy (:meth:`_Candidates.noise`) of the views that at least half agree with
    (a moving object is at a different place in each bracket: at any one place, most
    show what is behind it; the darkest bracket is so noisy that every other agrees
    with it), or with no such majority the view with the most agreement. (With a
    simple majority for the reference enough, a dark object only the reference and one
    other bracket showed, a few codes above black, was kept from the reference though
    more brackets agreed with the background: 4.5x the still stack's error,
    tests/test_align_hard_cases.py.) A bracket saturated there is never a source; under
    a clipped reference only brackets consistent with its bound (the radiance is at
    least its last usable code's) can be: a dark object that only a short bracket shows
    there is a ghost."""
    count = candidates.codes.shape[0]
    core = region & flagged.any(axis=0)  # the cells some bracket was found moving in
    others = [j for j in range(count) if j != reference]
    clipped = candidates.clipped_fraction(reference, box, region) > CLIPPED_SOURCE
    support = _agreement(flagged, judged, core, reference)
    best = (-1.0 if clipped else support, reference, flagged)
    majority = [] if clipped or support < 0.5 else [
        (candidates.noise(reference, box, region), reference, flagged)]
    for k in others:
        if clipped and np.count_nonzero(flagged[k] & core) > 0.5 * np.count_nonzero(core):
            continue
        mean, counts, _, far = (a[(slice(None), *box)] for a in candidates.test(k))
        told = (counts >= MIN_SAMPLES) & region
        against = (mean > limits[:, None, None]) & (far > FAR) & told
        against[k] = False
        agree = _agreement(against, told, core, k)
        # Whether k is saturated there is asked only of a view that would count.
        if (agree <= best[0] and agree < 0.5
                or candidates.clipped_fraction(k, box, region) > CLIPPED_SOURCE):
            continue
        if agree > best[0]:
            best = (agree, k, against)
        if agree >= 0.5:
            majority.append((candidates.noise(k, box, region), k, against))
    if best[1] == reference:
        return reference, flagged
    if majority:
        _, source, against = min(majority, key=lambda entry: entry[:2])
        return source, against
    return best[1], best[2]


def _agreement(against: np.ndarray, judged: np.ndarray, core: np.ndarray, source: int
               ) -> float:
    """The fraction of the other brackets' judged cells of ``core`` that agree with
    ``source`` (are not ``against`` it); 0 with none judged."""
    agree = total = 0
    for j in range(against.shape[0]):
        if j != source:
            told = judged[j] & core
            total += int(np.count_nonzero(told))
            agree += int(np.count_nonzero(told & ~against[j]))
    return agree / total if total else 0.0


def deghost(codes: np.ndarray, estimates: np.ndarray, variance: np.ndarray, reference: int,
            coverage: np.ndarray | None = None, cell: int = CELL,
            threshold: float = THRESHOLD, resampled: bool = True, *,
            excluded: np.ndarray | None = None, clip: tuple | None = None) -> Deghosting:
    """Keep weights for every bracket of ``codes`` (module docstring).

    Parameters
    ----------
    codes
        ``(P, H, W, C)`` code values, aligned, sorted by exposure.
    estimates
        ``(P, C, levels)``: ``x_j(z) = f^-1(z) / dt_j``, relative radiance.
    variance
        ``(P, C, levels)``: the variance of each estimate's disagreement (relative
        radiance squared, :func:`hdrio.align.consistency.consistency_variance`); ``inf``
        where a code says nothing (clipped, black).
    reference
        The bracket the others are tested against:
        :func:`hdrio.align.registration.best_exposed_bracket`. It need not be the bracket
        the others were aligned to; if it was warped, its own uncovered cells still go.
    coverage
        ``(P, rows, cols)`` cells each warped bracket covers (1) or not (0; 1 for the
        bracket the others were aligned to), or ``None``.
    resampled
        Whether the brackets were warped (then each is tested against the reference's
        3x3 range, not its pixel).
    excluded
        ``(P, H, W)`` observations kept out of the merge (``--exclude-color``,
        ``--mask``), or ``None``: a cell holding one, of the bracket or of the reference,
        says nothing about motion (Memorial's blue registration borders were flagged).
    clip
        The merge's saturation policy as its kernels take it
        (:meth:`hdrio.merge.saturation.ClipPolicy.kernel_args`) where it says the stack
        mixes its channels after the clip, else ``None``: an observation it drops whole
        is not tested (:func:`hdrio.align.consistency.cell_disagreement`), a clip bent
        every channel of it. (Where a stack does not mix, the clip test drops only gross
        disagreements with the shorter bracket, which a mover makes too, and every
        observation is tested: a dark mover crossing four brackets,
        tests/test_align_hard_cases.py, kept 20x the still stack's error where those
        observations went untested; 15x is its bound.)
    """
    import scipy.ndimage
    count, height, width, _ = codes.shape
    rows, cols = -(-height // cell), -(-width // cell)
    tables = test_tables(codes, estimates, variance, reference)
    if clip is None:
        clip = untested(estimates.shape[2] - 1, codes.shape[3])
    # The quick look. Its median cell says how far the noise model under-states the
    # noise (about 1 when it is right; 4.9 for frobisher's 1/8 s JPEG against its 8 s
    # with the interim model); the threshold is raised by that factor, up to
    # SCALED_MAX (a moving object's cells sit near the cap).
    stride = max(STRIDE * COARSE, int(math.sqrt(height * width / QUICK_SAMPLES)))
    size = stride * cell // STRIDE  # the fine test's samples a cell
    coarse, coarse_counts, _, _ = cell_disagreement(
        codes, tables, clip, reference, size, stride,
        np.ones((-(-height // size), -(-width // size)), bool), resampled)
    judged = coarse_counts >= MIN_SAMPLES
    scale = np.array([max(1.0, float(np.median(coarse[j][judged[j]]))) if judged[j].any()
                      else 1.0 for j in range(count)])
    limits = np.minimum(SCALED_MAX, threshold * scale)
    suspect = (coarse > (QUICK * scale)[:, None, None]) & judged
    suspect[reference] = False
    suspect = scipy.ndimage.binary_dilation(suspect.any(axis=0), np.ones((3, 3), bool))
    todo = _fine_cells(suspect, rows, cols, cell, size)
    keep = np.ones((count, rows, cols), np.float32)
    if coverage is not None:
        keep *= coverage
    if not todo.any():  # nothing disagrees anywhere (a still stack): no fine test
        return Deghosting(keep, cell, reference, 0.0)
    mean, counts, takeovers, far = cell_disagreement(codes, tables, clip, reference, cell,
                                                     STRIDE, todo, resampled)
    judged = counts >= MIN_SAMPLES
    if excluded is not None:
        held = _excluded_cells(excluded, cell, rows, cols)
        judged &= ~held & ~held[reference]
    if coverage is not None:  # a warp's invented border is dropped anyway, not motion
        judged &= (coverage >= 1.0) & (coverage[reference] >= 1.0)
    flagged = (mean > limits[:, None, None]) & (far > FAR) & judged
    flagged[reference] = False
    # A cell alone says little: JPEG's blocks and a scan's grain flag one cell here and
    # there on a still stack (a textured JPEG tripod stack: five, 17 % of it deghosted
    # once grown and feathered); a moving object fills cells side by side.
    labels, found = scipy.ndimage.label(flagged.any(axis=0), np.ones((3, 3), bool))
    sizes = np.bincount(labels.reshape(-1), minlength=found + 1)
    flagged &= (sizes >= MIN_CELLS)[labels][None]
    moving = scipy.ndimage.binary_dilation(flagged.any(axis=0), np.ones((3, 3), bool))
    if not moving.any():
        return Deghosting(keep, cell, reference, 0.0)
    labels, _ = scipy.ndimage.label(moving, np.ones((3, 3), bool))
    drop = np.zeros((count, rows, cols), bool)
    sources = np.full((rows, cols), -1, np.int8)
    candidates = _Candidates(codes, tables, clip, moving, cell, resampled)
    for label, box in enumerate(scipy.ndimage.find_objects(labels), start=1):
        region = labels[box] == label
        every = (slice(None), *box)
        source, against = _source(candidates, reference, box, region, flagged[every],
                                  judged[every], limits)
        drop[every] |= against & region
        drop[source][box][region] = False
        sources[box][region] = source
    dropped = np.zeros((rows, cols), bool)
    for j in range(count):
        if not drop[j].any():
            continue
        grown = scipy.ndimage.binary_dilation(drop[j], np.ones((3, 3), bool))
        soft = scipy.ndimage.gaussian_filter(grown.astype(np.float32), 1.0, mode="nearest")
        weight = np.maximum(grown, np.clip(2.0 * soft, 0.0, 1.0))
        weight[weight < 0.02] = 0.0
        weight[sources == j] = 0.0  # a region's source is its view: never dropped there
        # Where a shorter j stands in for a clipped reference it is the scene's only
        # observation: growing and feathering must not drop it there. (Not for a longer
        # j under a dark reference: dark clothes fall below the usable codes, and the
        # background a longer bracket shows there is a ghost.)
        weight[(takeovers[j] > counts[j]) & ~drop[j]] = 0.0
        keep[j] *= 1.0 - weight
        dropped |= weight > 0
    fraction = float(np.count_nonzero(dropped)) / dropped.size
    return Deghosting(keep, cell, reference, fraction, sources)
