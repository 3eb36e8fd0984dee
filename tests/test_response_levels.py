"""The levels a 16-bit response is solved at (hdrio/radiometry/levels.py), and the
well-exposed window of deep codes in light (hdrio.skips.well_exposed_codes)."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.job.options import MergeOptions
from hdrio.job.output import exr_attributes
from hdrio.job.run import merge_stack
from hdrio.radiometry.levels import code_of, level_of, solve_levels
from hdrio.radiometry.saved_response import response_from_header
from hdrio.response.debevec1997 import response_Debevec1997
from hdrio.skips import WELL_EXPOSED, well_exposed_codes
from tests.hard_cases import hand_held, tripod_stack


def test_levels_are_every_code_at_8_bits_and_toe_spaced_deeper():
    assert solve_levels(255) == (256, "even")
    assert solve_levels(65535) == (1024, "toe")
    codes = code_of(256, 255)
    assert np.array_equal(codes, np.arange(256)) and np.array_equal(level_of(codes, 255, 256),
                                                                    np.arange(256))
    deep = code_of(1024, 65535, "sqrt")
    assert deep[0] == 0 and deep[-1] == 65535 and np.all(np.diff(deep) > 0)
    assert np.allclose(level_of(deep, 65535, 1024, "sqrt"), np.arange(1024), atol=1e-9)
    # The shadows get the fine levels: code 100 is level 40 (evenly spaced: 1.6); the top
    # levels are 128 codes apart (evenly spaced: 64).
    assert level_of(100, 65535, 1024, "sqrt") == pytest.approx(39.96, abs=0.01)
    assert deep[-1] - deep[-2] == pytest.approx(128.0, abs=0.1)


def test_toe_levels_are_sqrt_in_the_shadows_and_even_above():
    """``toe``: evenly in sqrt(z) below a sixteenth of the range, evenly in z above, the
    spacing continuous at the join (no level twice as wide as its neighbour)."""
    deep = code_of(1024, 65535, "toe")
    assert deep[0] == 0 and deep[-1] == 65535 and np.all(np.diff(deep) > 0)
    assert np.allclose(level_of(deep, 65535, 1024, "toe"), np.arange(1024), atol=1e-9)
    steps = np.diff(deep)
    above = deep[:-1] >= 65535 / 16
    assert np.allclose(steps[above], 65535 * (1 + 1 / 16) / 1023)  # 68.07 codes
    below = deep[1:] < 65535 / 16
    assert np.allclose(np.diff(np.sqrt(deep[:-1][below])), np.diff(np.sqrt(deep[:-1][below]))[0])
    assert steps[0] < 0.3  # 0.28 codes: sqrt's fine levels where a linear curve bends
    join = np.flatnonzero(deep >= 65535 / 16)[0]
    assert steps[join - 2] == pytest.approx(steps[join], rel=0.02)  # no jump at the join


@pytest.mark.parametrize("curve,bound", [("dorf120", 0.012), ("dorf200", 0.044),
                                         ("emor-f0", 0.0075)])
def test_16_bit_curves_with_a_shoulder_or_a_toe_are_solved_at_toe_levels(
        shared_data, monkeypatch, curve, bound):
    """16-bit brackets of a real scene through real camera curves (the truth harness's
    renderer, 7 x 2 EV): the response's RMS error (stops, codes 4-96 % of the range)
    against the true curve. Levels evenly in sqrt(z) over the whole range (stop 52's
    choice for every deep curve) gave Desk 0.041 / 0.059 / 0.0036 stop, even levels
    0.031 / 0.045 / 0.0071; ``toe`` levels 0.0062 / 0.042 / 0.0037. Bounds: below both
    others where they are worse (DoRF 200: 0.044, between toe's 0.042 and even's 0.045;
    the render is seeded, so the solve is the same on every run)."""
    from benchmarks.truth.curves import load_curve
    from benchmarks.truth.metrics import response_rms_stops
    from benchmarks.truth.scenes import read_scene
    from benchmarks.truth.stacks import exposure_ladder
    from hdrio.stack import ExposureStack
    from hdrio.tools.synthetic import render_brackets

    truth = read_scene(shared_data("openexr_scenes") / "Desk.exr", width=200)
    times = exposure_ladder(truth, 7, 2.0)
    true_curve = load_curve(curve)
    codes = render_brackets(truth.radiance, times, true_curve.response, bit_depth=16, seed=3)
    stack = ExposureStack.from_arrays(codes, times, code_max=65535)
    response = response_Debevec1997(stack)
    assert response.parameters["spacing"] == "toe"
    error, _ = response_rms_stops(response.log_inverse, true_curve, 65535)
    assert error <= bound, error


def test_a_linear_16_bit_ladder_is_solved_to_ln_z_down_to_its_shadows():
    """A still linear 16-bit ladder (7 x 2 EV, a camera's noise): the solved g against
    ln z, relative to code 30000. On levels evenly spaced in code the smoothness term
    straightened ln z's bend at the bottom: +1.66-1.72 at code 100, +0.73-0.78 at 300,
    +0.07-0.09 at 1000, -0.03 at 3000 (this stack, the three channels). Measured now:
    0.11-0.38 at 100, 0.005-0.038 at 300, at most 0.017 from 1000 up. Bounds: 0.6, 0.1
    (an eighth of the old error) and 0.03."""
    response = response_Debevec1997(tripod_stack("16-bit", 0, 7, "GoldenGate").stack())
    assert response.parameters["spacing"] == "sqrt"  # toe first; ln z: solved again
    g = response.log_inverse

    def error(codes):
        codes = np.asarray(codes)
        return np.abs(g[codes] - g[30000] - np.log(codes / 30000)[:, None]).max()

    assert error([1000, 3000, 10000, 60000]) <= 0.03
    assert error([300]) <= 0.1
    assert error([100]) <= 0.6


def test_a_solved_16_bit_response_reads_back_from_the_header():
    """The header stores g at the solve's levels, sqrt spaced, and says so
    (hdrio:responseSpacing); read back, it is the merge's response. Measured: 1.4e-5 at
    most from code 64 up, 1.5e-3 below (the level codes are not whole codes: g is
    interpolated twice, and bends most at the bottom); bound 1e-4 from code 64 up."""
    result = merge_stack(tripod_stack("16-bit", 0, 5, "Desk", 60, 80).stack(),
                         MergeOptions(align="off", deghost="off"))
    header = exr_attributes(result)
    assert header["hdrio:responseSpacing"] == "sqrt" and header["hdrio:responseLevels"] == 1024
    back = response_from_header(header, "saved.exr")
    difference = np.abs(back.log_inverse - result.response.log_inverse)[64:]
    assert difference.max() <= 1e-4, difference.max()


def test_the_levels_benchmark_forces_each_spacing(shared_data):
    """``python -m benchmarks.levels`` compares spacings by forcing each on the job:
    forced, the response says so; ``auto`` is the job's own choice (``sqrt`` for linear
    codes). Its numbers are in docs/method.md."""
    from benchmarks.levels import rows_for, summary

    shared_data("openexr_scenes")
    with pytest.MonkeyPatch.context() as patch:
        seen = []
        import hdrio.response.debevec1997 as debevec

        solve = debevec.response_Debevec1997
        patch.setattr(debevec, "response_Debevec1997",
                      lambda *a, **k: seen.append(k.get("spacing")) or solve(*a, **k))
        patch.setattr("hdrio.job.stages.RESPONSE_METHODS",
                      {"Debevec1997": debevec.response_Debevec1997})
        even = rows_for("even", 80, ("linear",), ("Desk",))
        assert set(seen) == {"even"}
        seen.clear()
        auto = rows_for("auto", 80, ("linear",), ("Desk",))
        assert set(seen) == {"sqrt"}
    assert summary(even, "linear")["stacks"] == summary(auto, "linear")["stacks"] == 2


def test_linear_16_bit_files_without_exposures_get_sqrt_levels(tmp_path):
    """Linear 16-bit TIFFs with no exposure metadata (``--exposures-from-data``): the
    spacing is decided on the first stack the job solves, whose exposures are inferred
    from the pixels. Decided on the files as read, whose placeholder exposures are 1, 2,
    3, 4, 5, it was ``toe``."""
    from hdrio.io.brackets import read_brackets
    from hdrio.io.write import write_image

    case = tripod_stack("16-bit", 0, 5, "Desk", 100, 150)
    files = [write_image(tmp_path / f"linear_{j}.tif", frame, "uint16")
             for j, frame in enumerate(case.codes)]
    stack = read_brackets(files, infer_exposures=True)
    result = merge_stack(stack, MergeOptions(exposures_from_data=True))
    assert result.response.parameters["spacing"] == "sqrt"


def test_a_toe_spaced_response_reads_back_from_the_header():
    """A gamma-encoded 16-bit ladder is solved at ``toe`` levels; the header says so and
    reads back as the merge's response. Measured: 3.3e-6 at most from code 64 up; bound
    1e-4 as for ``sqrt`` levels."""
    case = tripod_stack("16-bit", 0, 5, "Desk", 60, 80)
    codes = np.rint(65535 * (case.codes / 65535.0) ** (1 / 2.2)).astype(np.uint16)
    stack = type(case.stack()).from_arrays(codes, case.exposures, code_max=65535)
    result = merge_stack(stack, MergeOptions(align="off", deghost="off"))
    header = exr_attributes(result)
    assert header["hdrio:responseSpacing"] == "toe" and header["hdrio:responseLevels"] == 1024
    back = response_from_header(header, "saved.exr")
    difference = np.abs(back.log_inverse - result.response.log_inverse)[64:]
    assert difference.max() <= 1e-4, difference.max()


def test_deep_codes_spacing_is_decided_on_matched_quantiles():
    """deep_spacing: a linear sensor's 16-bit ladders get ``sqrt`` levels, still or
    hand-held (unregistered, the curve solved on pixel samples had slopes 0.77-1.23 and
    could not tell), a gamma-2.2 one ``toe``; 8-bit codes ``even``. Measured on the
    quantiles: slopes 0.95-1.09 on hand-held linear ladders, 1.21-1.24 on DoRF 200."""
    from hdrio.response.debevec1997 import deep_spacing

    assert deep_spacing(tripod_stack("16-bit", 0, 7).stack()) == "sqrt"
    for seed, scene in ((0, "GoldenGate"), (0, "StillLife"), (1, "Desk")):
        assert deep_spacing(hand_held(7, seed, scene=scene, encoding="16-bit").stack()) == "sqrt"
    linear = tripod_stack("16-bit", 0, 7)
    codes = np.rint(65535 * (linear.codes / 65535.0) ** (1 / 2.2)).astype(np.uint16)
    gamma = type(linear.stack()).from_arrays(codes, linear.exposures, code_max=65535)
    assert deep_spacing(gamma) == "toe"
    assert deep_spacing(tripod_stack("png", 0, 7).stack()) == "even"


def test_an_8_bit_header_says_its_levels_are_every_code():
    result = merge_stack(tripod_stack("png", 0, 3, "Desk", 60, 80).stack(),
                         MergeOptions(align="off", deghost="off"))
    header = exr_attributes(result)
    assert header["hdrio:responseSpacing"] == "even" and header["hdrio:responseLevels"] == 256
    back = response_from_header(header, "saved.exr")
    assert np.array_equal(back.log_inverse, result.response.log_inverse)


def test_a_header_with_an_unknown_spacing_is_refused():
    from hdrio.errors import InputError

    result = merge_stack(tripod_stack("png", 0, 3, "Desk", 60, 80).stack(),
                         MergeOptions(align="off", deghost="off"))
    header = {**exr_attributes(result), "hdrio:responseSpacing": "log"}
    with pytest.raises(InputError, match="saved.exr.*responseSpacing"):
        response_from_header(header, "saved.exr")


def _inverse(curve, code_max=65535, channels=3):
    z = np.arange(code_max + 1, dtype=np.float64) / code_max
    return np.repeat(curve(z)[None], channels, axis=0)


def test_deep_codes_window_reaches_as_far_in_light_as_srgb_codes_do():
    """5 % of an sRGB range is 7.8 stops under its 95 %; of a linear range only 4.3. A
    linear 16-bit response's window now reaches 7.8 stops (code 276, not 3277); a
    gamma-2.2 one's 5 % is already further down in light and stays; 8-bit codes keep
    their fractions whatever the response."""
    linear = _inverse(lambda z: z)
    low, high = well_exposed_codes(65535, WELL_EXPOSED, linear)
    assert high == well_exposed_codes(65535)[1]
    assert np.log2(high / low) == pytest.approx(np.log2(0.8902 / 0.003935), abs=0.01)
    assert low < well_exposed_codes(65535)[0] / 10
    gamma = _inverse(lambda z: z**2.2)
    assert well_exposed_codes(65535, WELL_EXPOSED, gamma) == well_exposed_codes(65535)
    eight = _inverse(lambda z: z, 255)
    assert well_exposed_codes(255, WELL_EXPOSED, eight) == well_exposed_codes(255)
    assert well_exposed_codes(65535, (0.02, 0.95), linear)[0] < 120  # 9.2 stops: 108


@pytest.mark.parametrize("scene,seed", [("GoldenGate", 0), ("StillLife", 2), ("Desk", 0)])
def test_a_hand_held_linear_16_bit_ladder_is_registered(scene, seed):
    """Hand-held linear 16-bit ladders (7 x 2 EV, up to 6 px and 0.3 degrees, a sun):
    every bracket but the longest (its sun and sky clipped: refused, as at 8 bits)
    within 0.5 px of its true warp. With the window of the code fractions and the
    response solved on evenly spaced levels, GoldenGate's two shortest were registered
    by their highlights alone, 1.6 and 1.05 px off; StillLife's five 3.8-4.5 px off
    (seed 2), or all but the reference refused (seed 0); Desk's 0.1-0.4 px, to the
    longest bracket. Measured now: at most 0.17, 0.14 and 0.06 px."""
    case = hand_held(7, seed, scene=scene, encoding="16-bit")
    alignment = merge_stack(case.stack(), MergeOptions(deghost="off")).motion.alignment
    refused = {j for j, _ in alignment.refused}
    assert refused <= {6}, alignment.refused
    errors = [e for j, e in enumerate(case.corner_errors(alignment)) if j not in refused]
    assert max(errors) < 0.5, errors


def test_a_hand_held_linear_16_bit_ladders_exposures_agree_with_its_metadata():
    """The exposure check compared linear brackets over 15-90 % of the range (2.6
    stops; neighbours 2 EV apart shared 0.6): on this ladder it measured the two
    shortest 0.56-0.59 stop brighter than they are (the metadata is exact), warned, and
    deghosting's test would have read them. Its window now reaches as far down in light
    as on sRGB codes (hdrio.merge.exposure_check.compared_codes). Measured: at most
    0.025 stop; bound 0.1 (the warning is at 1/6)."""
    case = hand_held(7, 1, encoding="16-bit", height=400, width=600)
    result = merge_stack(case.stack(), MergeOptions())
    assert result.exposures.warnings("explicit") == []
    stops = np.log2(result.exposures.estimated / case.exposures)
    assert np.max(np.abs(stops)) <= 0.1, stops


def test_a_solved_curve_is_called_linear_only_when_it_is():
    """linear_deviation: linear 16-bit ladders solve to ln z within 0.003-0.012 (slope
    0.999-1.001); a gamma-2.2 16-bit ladder to slope 2.19; an sRGB 8-bit one is not
    linear either."""
    from hdrio.radiometry.curve import linear_deviation

    deviation = linear_deviation(response_Debevec1997(tripod_stack("16-bit", 0, 7).stack()))
    assert deviation is not None and deviation <= 0.03
    assert linear_deviation(response_Debevec1997(tripod_stack("png", 0, 7).stack())) is None
    gamma = tripod_stack("16-bit", 0, 7)
    codes = np.rint(65535 * (gamma.codes / 65535.0) ** (1 / 2.2)).astype(np.uint16)
    stack = type(gamma.stack()).from_arrays(codes, gamma.exposures, code_max=65535)
    assert linear_deviation(response_Debevec1997(stack)) is None


def test_the_summary_names_linear_codes(tmp_path, capsys):
    """Linear 16-bit TIFFs merged with the solved response: the summary says their curve
    is linear and that --response linear merges them without a solve (on linear 16-bit
    ladders 3-15 % less median error, docs/method.md); with --response linear, or
    gamma-encoded brackets, it says nothing."""
    from hdrio.io.write import write_image
    from tests.conftest import run_cli

    case = tripod_stack("16-bit", 0, 5, "Desk", 100, 150)
    files = [write_image(tmp_path / f"lin_{j}.tif", frame, "uint16")
             for j, frame in enumerate(case.codes)]
    times = ",".join(f"{t:.9g}" for t in case.exposures)
    hint = "--response linear merges without a solve"
    code, out, err = run_cli(capsys, "merge", *files, "--exposures", times,
                             "-o", tmp_path / "solved.exr")
    assert code == 0, err
    assert hint in out + err
    code, out, err = run_cli(capsys, "merge", *files, "--exposures", times, "--response",
                             "linear", "-o", tmp_path / "linear.exr")
    assert code == 0 and hint not in out + err
    srgb = tripod_stack("png", 0, 5, "Desk", 100, 150)
    pngs = [write_image(tmp_path / f"srgb_{j}.png", frame, "uint8")
            for j, frame in enumerate(srgb.codes)]
    code, out, err = run_cli(capsys, "merge", *pngs, "--exposures", times,
                             "-o", tmp_path / "srgb.exr")
    assert code == 0 and hint not in out + err
