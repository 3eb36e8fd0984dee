"""Deghosting where the reference is black: it bounds the radiance from above.

Dark clothes in the reference bracket fall below its usable codes; the other brackets
show the brighter floor behind where the person stood when they were taken. Such a
reference still says the radiance is at most its first usable code's estimate, so those
brackets are inconsistent with it (tested), not stand-ins for it: taken over untested,
the floor merged channel by channel with the reference's dark codes, in coloured speckle
(HDR Toolbox's ghost/ stack). The region then keeps one view (hdrio.align.deghost).
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_stack
from hdrio.stack import ExposureStack
from hdrio.tools.synthetic import gamma_inverse_response, render_brackets

TIMES = (0.01, 0.04, 0.16)
PERSON = (slice(56, 88), slice(64, 96))


def _stacks():
    rng = np.random.default_rng(4)
    # A smooth floor over about 6 stops (each bracket loses some of it to black or to
    # clipping, so that the middle one, the reference, is the best exposed).
    log = scipy.ndimage.gaussian_filter(rng.normal(0.0, 1.0, (144, 160)), 12.0)
    floor = np.exp(1.5 * log / log.std())[..., None] * np.array([0.45, 0.5, 0.4])
    with_person = floor.copy()
    with_person[PERSON] = (0.0065, 0.007, 0.006)  # near black at 0.04 s (codes ~6)
    still = render_brackets(floor, TIMES, seed=1)
    moved = still.copy()
    moved[1] = render_brackets(with_person, TIMES, seed=1)[1]  # the reference
    return still, moved, with_person


def test_a_person_only_the_black_reference_shows_is_one_consistent_view():
    """The reference shows dark clothes (near black) where the other two brackets show
    the floor: the region keeps one view, the one most brackets agree with (the floor,
    seen well by both), never one channel from each (the speckle this stack once gave:
    one channel from the floor, the others dark). Before the consistent labelling of
    issue 28 the reference's dark view was kept; either is one snapshot."""
    still, moved, truth = _stacks()
    response = gamma_inverse_response()[0]
    options = MergeOptions(align="off", deghost="auto")
    result = merge_stack(ExposureStack.from_arrays(moved, TIMES), options, response=response)
    assert result.motion.deghosting.reference == 1
    keep = result.motion.keep
    inner = (slice(PERSON[0].start // 8 + 1, PERSON[0].stop // 8 - 1),
             slice(PERSON[1].start // 8 + 1, PERSON[1].stop // 8 - 1))
    assert keep[1][inner].max() == 0.0  # the reference's view of the person dropped
    assert keep[0][inner].min() == 1.0 and keep[2][inner].min() == 1.0
    inside = (slice(PERSON[0].start + 8, PERSON[0].stop - 8),
              slice(PERSON[1].start + 8, PERSON[1].stop - 8))
    plain = merge_stack(ExposureStack.from_arrays(still, TIMES), options, response=response)
    # Every channel is the floor's, as the still stack merges it (noise: measured 1.4 %).
    ratio = result.radiance[inside] / plain.radiance[inside]
    assert np.abs(ratio - 1).max() < 0.05, np.abs(ratio - 1).max()
    # And the floor away from the person is merged as before (measured 1.1 %).
    away = (slice(0, 24), slice(None))
    assert np.abs(result.radiance[away] / plain.radiance[away] - 1).max() < 0.03


def test_a_dark_still_region_is_not_flagged():
    """A dark patch that is dark in every bracket (a still scene): the longer bracket
    is within the reference's bound and takes over; nothing is dropped."""
    _, _, truth = _stacks()
    codes = render_brackets(truth, TIMES, seed=2)
    result = merge_stack(ExposureStack.from_arrays(codes, TIMES),
                         MergeOptions(align="off", deghost="auto"),
                         response=gamma_inverse_response()[0])
    assert result.motion.deghosting.fraction == 0.0
