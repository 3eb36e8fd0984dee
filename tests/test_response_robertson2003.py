"""Robertson et al. (2003): Debevec's response refined by maximum likelihood."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.response import RESPONSE_METHODS
from hdrio.stack import ExposureStack
from hdrio.tools.synthetic import demo_scene, render_brackets

CODES = np.arange(20, 236)  # away from the ends, where neither method is constrained


def _rms_stops(g: np.ndarray, truth: np.ndarray) -> float:
    difference = g - truth
    difference -= difference.mean()  # responses are known up to a scale
    return float(np.sqrt(np.mean(difference**2)) / np.log(2))


@pytest.mark.parametrize("curve_name", ["dorf50", "emor-f0"])
def test_the_refined_response_stays_near_the_truth(curve_name, shared_data):
    """On the demo scene shot with an irregular 6-bracket ladder (no ambiguity: the ratios
    are not powers of one), every channel's refined curve is within 0.015 stop RMS of
    the true one over codes 20-235 (about 1 %; measured 0.0038-0.0064 on the green
    channel, Debevec's 0.0018-0.0040), finite and non-decreasing, and the parameters
    say how it was made."""
    shared_data("crf_database")
    from benchmarks.truth.curves import load_curve

    curve = load_curve(curve_name)
    times = np.array([1 / 300, 1 / 90, 1 / 25, 1 / 8, 0.4, 1.3])
    stack = ExposureStack.from_arrays(
        render_brackets(demo_scene(300, 400), times, curve.response, seed=1), times)
    response = RESPONSE_METHODS["robertson"](stack)
    assert response.method == "Robertson2003"
    assert 1 <= response.parameters["iterations"] <= 3
    assert response.parameters["refined_pixels"] > response.parameters["samples"]
    g = response.log_inverse
    assert np.all(np.isfinite(g)) and np.all(np.diff(g, axis=0) >= 0)
    assert np.allclose(g[128], 0.0)
    truth = curve.log_inverse(CODES, 255)
    for c in range(3):
        assert _rms_stops(g[CODES, c], truth) < 0.015, c


def test_it_takes_the_toe_heavy_curve_closer_than_debevec(shared_data):
    """The truth harness's core stack Desk / DoRF 200 (7 frames 2 EV apart): Debevec's
    smoothness term leaves the strong toe 0.046 stop RMS off; the refinement brings it
    to 0.0397 (measured with the noise model of issue 28, whose terms are never zero
    and which weights the toe's codes less; 0.035 with the earlier model), asserted: at
    least 10 % closer. (It is not the default: over the harness it is no better,
    docs/accuracy.md.)"""
    shared_data("openexr_scenes"), shared_data("crf_database")
    from benchmarks.truth.curves import load_curve
    from benchmarks.truth.methods import exposure_stack
    from benchmarks.truth.metrics import response_rms_stops
    from benchmarks.truth.scenes import builtin_scenes
    from benchmarks.truth.stacks import StackSpec, render_stack

    curve = load_curve("dorf200")
    (scene,) = builtin_scenes(("Desk",), width=400)
    stack = exposure_stack(render_stack(StackSpec("Desk", "dorf200"), scene, curve))
    debevec = response_rms_stops(RESPONSE_METHODS["Debevec1997"](stack).log_inverse,
                                 curve, 255)[0]
    refined = response_rms_stops(RESPONSE_METHODS["Robertson2003"](stack).log_inverse,
                                 curve, 255)[0]
    assert refined < 0.9 * debevec, (refined, debevec)


def test_cli_records_the_method(brackets, tmp_path, capsys):
    """``--response Robertson2003`` (the shared option table: the chain's ``--merge``
    takes it too) is written to the header and the summary."""
    from hdrio.io.header import read_header
    from tests.conftest import run_cli

    output = tmp_path / "r.exr"
    code, out, err = run_cli(capsys, "merge", *brackets, "--response", "Robertson2003",
                             "-o", output)
    assert code == 0, err
    assert "response:  Robertson2003" in out
    assert read_header(output)["hdrio:responseMethod"] == "Robertson2003"
