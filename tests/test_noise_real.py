"""The noise model on real captures and on generated phone-like night stacks (issue 28).

Two measures (``benchmarks/noise_model.py``, which prints the full tables):
the measured disagreement of neighbouring brackets over the model's prediction, per
channel and decile of brightness; and in the dark (the longest unclipped bracket at codes
5-30), the default merge over that bracket's own estimate.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.noise_model import (
    BOUNDS,
    border_of,
    dark_ratios,
    dark_within,
    disagreement_deciles,
    real_stacks,
)
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_stack
from tests.hard_cases import night_stack


@pytest.fixture(scope="module")
def real(shared_data):
    shared_data("memorial_debevec")  # skip without the data
    shared_data("hdrtoolbox_stacks")
    shared_data("frobisher_001")
    return {name: (stack, options) for name, stack, options in real_stacks()}


@pytest.mark.parametrize("name, share", [("memorial", 0.85), ("frobisher", 0.95),
                                         ("ghost", 0.8), ("alignment", 0.7)])
def test_the_fitted_model_predicts_real_disagreement(real, name, share):
    """Predicted against measured disagreement of neighbouring brackets, per decile of
    brightness and channel (``python -m benchmarks.noise_model``), the merge's defaults.
    Measured (this code): memorial 0.78-1.31 (27 of its 30 deciles within the issue's
    0.8-1.25), frobisher 29 of 30 (30 before issue 29 solved the response without the
    observations at the clip; red's 8th decile is 1.36 now), ghost 0.86-1.52 (25), alignment
    0.69-1.77 (24: its laundry and leaves in the wind, warped); the outliers in the
    brightest and darkest deciles, where a camera's roll-off and JPEG's chroma bend what the
    four terms cannot follow. Before: 0.2-3.8, every term but the JPEG floor 0 on the JPEG
    stacks. The two warped stacks' counts move with the response solve's sample: over
    ``--seed`` 0-3, ghost 25, 25, 25, 26 and alignment 24, 25, 24, 22 (26, 26, 26, 27 and
    21, 21, 21, 20, up to 1.79, until the re-solve's sample was blurred alike,
    docs/motion.md).
    Bounds here: every decile within 0.5-1.8, ``share`` of them within the issue's; and
    no term is zero."""
    stack, options = real[name]
    result = merge_stack(stack, options)
    noise = result.noise
    for term in ("shot", "read", "code"):
        assert np.all(getattr(noise, term) > 0), (term, noise.attributes())
    origin = noise.attributes()["hdrio:noiseOrigin"]  # fitted or floored, per term
    assert all(f"{term} " in origin for term in ("shot", "read", "code", "relative"))
    ratios, counted = disagreement_deciles(
        result.stack.codes, result.stack.channel_exposures, result.response, noise,
        result.statistics.limits, border_of(result.stack, options))
    assert np.all(counted > 1000)
    assert np.all((ratios > 0.5) & (ratios < 1.8)), ratios
    inside = (ratios >= BOUNDS[0]) & (ratios <= BOUNDS[1])
    assert np.mean(inside) >= share, ratios


@pytest.mark.parametrize("name", ["memorial", "frobisher"])
def test_the_dark_keeps_to_the_longest_unclipped_bracket_on_real_stacks(real, name):
    """Where the longest unclipped bracket reads codes 5-30: the default merge over that
    bracket's own estimate, per channel, median within 3 % of 1 and 5th-95th percentiles
    within 0.8-1.25 (the issue's bound). Measured: memorial's blue (the only channel with
    such pixels; its film's fog is at code 15) 0.91 / 1.00 / 1.14; frobisher 1.000 in
    all three. (alignment/ has two such pixels: its dark corners are the warp's
    uncovered border.) Before: memorial 0.35 / 0.73 / 1.02 (the short brackets'
    near-black codes, on a curve extrapolated below code 12, carried the weight).

    Not ghost/: its dark pixels are mostly the walkers' dark clothes, where deghosting
    keeps the floor another bracket saw (1.00 / 1.00 / 4.2-6.0; with --deghost off,
    1.00 / 1.00 / 1.03-1.05: test_the_dark_of_ghost_without_deghosting)."""
    stack, options = real[name]
    result = merge_stack(stack, options)
    ratios = dark_ratios(result, border_of(result.stack, options))
    assert dark_within(ratios) and ratios[:, 0].max() >= 1000, ratios


def test_the_dark_of_ghost_without_deghosting(real):
    """ghost/'s dark pixels, the walkers' clothes, merged without deghosting: the
    estimator alone keeps to the longest unclipped bracket (measured 1.000 / 1.000 /
    1.03-1.05 against the issue's 0.8-1.25; before: 1.000 / 1.011-1.018 / 1.27-1.35)."""
    from dataclasses import replace

    stack, options = real["ghost"]
    result = merge_stack(stack, replace(options, deghost="off"))
    assert dark_within(dark_ratios(result))


@pytest.mark.parametrize("encoding", ["jpeg", "png"])
def test_no_confetti_in_a_phone_night_stack(encoding):
    """A phone's night bracket (9 frames 1/250 to 1 s, ISO-1000-like noise, noise
    reduction, a strong toe; tests/hard_cases.py): the dark grating keeps to the 1 s
    frame (measured: JPEG 1.000 / 1.000 / 1.000, PNG 0.94 / 1.00-1.02 / 1.09-1.15); the
    log merge is 1.44-1.47x at the median and up to 2.96x at the 95th percentile (the
    confetti). Its brackets' disagreement is predicted within the issue's bounds in
    every decile but one (measured 0.79-1.09)."""
    case = night_stack(seed=0, encoding=encoding)
    result = merge_stack(case.stack(), MergeOptions())
    assert dark_within(dark_ratios(result))
    log = dark_ratios(merge_stack(case.stack(), MergeOptions(merge="log")))
    assert np.all(log[:, 2] > 1.2)  # the measure sees the confetti it is there to catch
    ratios, _ = disagreement_deciles(result.stack.codes, result.stack.channel_exposures,
                                     result.response, result.noise)
    assert np.all((ratios > 0.7) & (ratios < 1.3)), ratios
