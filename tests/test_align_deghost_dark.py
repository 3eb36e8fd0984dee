"""Deghosting where the reference is black: it bounds the radiance from above.

Dark clothes in the reference bracket fall below its usable codes; the other brackets
show the brighter floor behind where the person stood when they were taken. Such a
reference still says the radiance is at most its first usable code's estimate, so those
brackets are inconsistent (tested, dropped), not stand-ins for it: taken over untested,
the floor merged channel by channel with the reference's dark codes, in coloured speckle
(HDR Toolbox's ghost/ stack).
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


def test_a_black_reference_drops_the_brighter_brackets_behind_it():
    still, moved, truth = _stacks()
    response = gamma_inverse_response()[0]
    options = MergeOptions(align="off", deghost="auto")
    result = merge_stack(ExposureStack.from_arrays(moved, TIMES), options, response=response)
    assert result.motion.deghosting.reference == 1
    keep = result.motion.keep
    inner = (slice(PERSON[0].start // 8 + 1, PERSON[0].stop // 8 - 1),
             slice(PERSON[1].start // 8 + 1, PERSON[1].stop // 8 - 1))
    # Both other brackets dropped inside the person (cells of 8 px, away from the edge).
    assert keep[0][inner].max() == 0.0 and keep[2][inner].max() == 0.0
    inside = (slice(PERSON[0].start + 8, PERSON[0].stop - 8),
              slice(PERSON[1].start + 8, PERSON[1].stop - 8))
    person = result.radiance[inside]
    plain = merge_stack(ExposureStack.from_arrays(still, TIMES), options, response=response)
    # The person comes from the dark reference alone (a few codes, noisy, some at 0),
    # never the floor behind in any channel (before: one channel from the floor, the
    # others dark: speckle). The floor there is at least 10x brighter than any channel.
    assert person.max() < 0.1 * plain.radiance[inside].min(), (
        person.max(), plain.radiance[inside].min())
    # Its mean colour is the person's (0.0065, 0.007, 0.006): within the noise of ~1000
    # pixels at ~6 codes, 30 %.
    colour = person.reshape(-1, 3).mean(axis=0)
    assert np.allclose(colour / colour[1], (0.93, 1.0, 0.86), rtol=0.3), colour
    # And the floor away from the person is merged as before.
    away = (slice(0, 24), slice(None))
    # (The noise model is fitted from each stack: the weights differ a little. Measured
    # 1.1 %.)
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
