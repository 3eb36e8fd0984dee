"""Alignment and deghosting on the generated hard cases of issue 28 (tests/hard_cases.py):
movers kept at most once, still stacks left alone, hand-held ladders registered, one rule
for the reference said the same way everywhere."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_stack
from hdrio.skips import WELL_EXPOSED, well_exposed_codes
from hdrio.tools.synthetic import radiance_error, well_exposed
from tests.hard_cases import (
    hand_held,
    hand_held_walkers,
    linear_still_life,
    mover_error,
    movers,
    movers_kept,
    night_stack,
    tripod_stack,
    walkers,
)

pytestmark = pytest.mark.usefixtures("scenes")


@pytest.fixture(scope="module")
def scenes():
    from benchmarks.truth.scenes import data_root

    if not (data_root() / "openexr_scenes").is_dir():
        pytest.skip("../shared/data/openexr_scenes not found: third-party test images are "
                    "read in place, not shipped; see README")


@pytest.mark.parametrize("bright", [True, False], ids=["bright", "dark"])
@pytest.mark.parametrize("large", [True, False], ids=["large", "small"])
@pytest.mark.parametrize("crossing", [2, 4, 5])
def test_no_mover_is_kept_from_two_brackets(bright, large, crossing):
    """A textured object 4x brighter or 1/4 as bright as the background, 5 % or 0.6 %
    of the frame, at a different place in each of 2, 4 or 5 of five brackets (a
    stained-glass window, clipped in most brackets: the hardest of the scenes tried).
    At every bracket's footprint the merge shows that bracket's view of it (``object``)
    at most once, and never two views mixed (``blend``; ``bound``, a clip's lower bound
    where only the object's bracket saw the background, is neither); before: the object
    kept twice in 5 of these 12 cases, 'blends' in 6.

    The movers' region against the one bracket's scene it fits best, over the still
    stack's error there, bound the issue's 3x: measured 1.19-1.58x for the bright
    objects, 1.10-1.62x for the dark ones. Before the rules of the next two tests and
    the falling codes left out of the re-solve (:func:`hdrio.align.motion.deghost_step`:
    the small dark object crossing five brackets is next to a clipped channel everywhere
    in the longest bracket, never found, and bent the curve: 3.29x) 1.20-2.44x and
    2.48-11.26x; before any deghosting 4-47x."""
    case = movers(crossing=crossing, bright=bright, large=large)
    still = movers(crossing=0, bright=bright, large=large)
    result = merge_stack(case.stack(), MergeOptions())
    held = merge_stack(still.stack(), MergeOptions())
    mask = well_exposed(still.codes, still.camera.code_max)
    scale = radiance_error(result.radiance, case.background, mask)["scale"]
    shown = movers_kept(case, result.radiance, scale)
    assert shown.count("object") <= 1 and "blend" not in shown, shown
    still_scale = radiance_error(held.radiance, still.background, mask)["scale"]
    moving = mover_error(case, result.radiance, scale, mask)
    steady = mover_error(case, held.radiance, still_scale, mask)
    assert moving <= 3 * steady, (moving, steady)


@pytest.mark.parametrize("crossing", [4, 5])
def test_a_dark_mover_where_the_reference_clips_is_found(crossing):
    """A dark object that only the longest bracket shows, in front of a background that
    the reference and the brackets between clip (and only the shortest sees): the longer
    brackets were tested against the reference's clip alone, "at least this bright",
    which a quarter of the background still passes. At 4 crossings 34 % of it was
    found, the rest bent the re-solved response (ln f^-1 at code 240: 1.76 against the
    still stack's 1.39) and the whole image's error went 8x the still stack's. Now the
    longer brackets are tested against the shorter bracket that took over for the
    clipped reference: all of it is found, and the error outside the movers' region is
    1.08x the still stack's. At 5 crossings the first test, on the bent curve, found 40 %
    of the image moving, the test on the curve solved without that 56 %: solved only
    once, the curve was still 0.13 off at code 240 and the error 4.6x; solved again
    without the 56 %, 1.05x. Bound 1.5x."""
    case = movers(crossing=crossing, bright=False, large=True)
    still = movers(crossing=0, bright=False, large=True)
    result = merge_stack(case.stack(), MergeOptions())
    held = merge_stack(still.stack(), MergeOptions())
    shown = result.motion.deghosting.motion_mask(*result.radiance.shape[:2]) > 0
    for footprint in case.objects:
        if footprint is not None:
            assert np.mean(shown[footprint]) > 0.95
    mask = well_exposed(still.codes, still.camera.code_max)
    outside = mask & ~np.any([f for f in case.objects if f is not None], axis=0)

    def error(merged, scene):
        scale = radiance_error(merged.radiance, scene, outside)["scale"]
        return float(np.median(np.abs(scale * merged.radiance[outside] / scene[outside] - 1)))

    assert error(result, case.background) <= 1.5 * error(held, still.background)


def test_a_mover_only_the_reference_shows_is_left_out_where_most_agree():
    """A dark object 0.6 % of the frame in two of five brackets, one of them the
    deghosting's reference. The region kept the reference's view, the object a few codes
    above black, whenever half the others agreed with it, though more agreed with
    another bracket's (the background): 4.49x the still stack's error. A region now keeps
    the reference's view only when no other view has more agreement; measured 1.39x
    (bound 2x)."""
    case = movers(crossing=2, bright=False, large=False)
    still = movers(crossing=0, bright=False, large=False)
    result = merge_stack(case.stack(), MergeOptions())
    held = merge_stack(still.stack(), MergeOptions())
    mask = well_exposed(still.codes, still.camera.code_max)
    scale = radiance_error(result.radiance, case.background, mask)["scale"]
    still_scale = radiance_error(held.radiance, still.background, mask)["scale"]
    assert movers_kept(case, result.radiance, scale) == ["background", "background"]
    moving = mover_error(case, result.radiance, scale, mask)
    assert moving <= 2 * mover_error(case, held.radiance, still_scale, mask)


@pytest.mark.parametrize("ev,seed", [(1.0, 0), (1.5, 2), (2.0, 0)])
def test_a_figure_in_every_bracket_is_kept_from_one(ev, seed):
    """A dark figure at overlapping places in each of three JPEG brackets
    (:func:`tests.hard_cases.walkers`). It bent the first response, and the noise fit
    took what that left for noise (relative noise 0.04-0.10 against a still stack's
    0.000-0.006): nothing was deghosted at 1 EV (seed 0) and 1.5 EV (seed 2), and the
    figure came out of all three places as coloured speckle, 8.3-8.9x the still stack's
    error against the best-fitting bracket's scene. The response's samples whose codes
    fall with exposure now send it to be solved again without them
    (:data:`hdrio.align.motion.FALLING`). Measured over 1, 1.5 and 2 EV, seeds 0-2:
    every one deghosted, 1.35-1.79x (the figure from one bracket alone, its noise;
    1.4-4.6x while the response was solved again only once,
    :data:`hdrio.align.motion.RESOLVES`, and without the falling pixels,
    :data:`hdrio.align.motion.FALLING_LEFT`); bound 3x, under the 8.3x of a blend. (How
    fragile the first pass was: with each place a third of the figure's width on, not
    0.35, all nine were found before too.)"""
    case, still = walkers(ev, seed), walkers(ev, seed, moving=False)
    result = merge_stack(case.stack(), MergeOptions())
    held = merge_stack(still.stack(), MergeOptions())
    assert result.motion.deghosting.fraction > 0.05
    mask = well_exposed(still.codes, still.camera.code_max)
    region = np.any(case.objects, axis=0) & mask

    def error(radiance, scene):
        scale = radiance_error(radiance, scene, mask & ~region)["scale"]
        return float(np.median(np.abs(scale * radiance[region] / scene[region] - 1)))

    kept = min(error(result.radiance, scene) for scene in case.scenes)
    assert kept <= 3 * error(held.radiance, still.scenes[0]), kept


@pytest.mark.parametrize("scene", [
    "Desk",
    pytest.param("MtTamWest", marks=pytest.mark.xfail(strict=True, reason=(
        "a textured figure before a plain sky leads registration: measured 1.76-6.89 px "
        "(docs/motion.md, 'Found, not fixed')")))])
def test_a_hand_held_stack_with_a_walker_is_registered(scene):
    """A figure walking through a hand-held 5 x 2 EV JPEG ladder
    (:func:`tests.hard_cases.hand_held_walkers`, seed 1): every bracket within 0.5 px of
    its true warp at the corners (the issue's bound for registration), as the same stack
    without the figure is (measured 0.00-0.12 px on both scenes). Desk: measured
    0.06-0.23 px with the figure."""
    case = hand_held_walkers(scene, seed=1)
    result = merge_stack(case.stack(), MergeOptions())
    errors = case.corner_errors(result.motion.alignment)
    assert not result.motion.alignment.refused and max(errors) < 0.5, errors


@pytest.mark.parametrize("scene,frames,ev,seed", [
    ("Desk", 3, 1.5, 1), ("StillLife", 5, 2.0, 0), ("StillLife", 5, 2.0, 1),
    ("GoldenGate", 7, 2.0, 1), ("GoldenGate", 7, 2.0, 2)])
def test_a_hand_held_ladder_is_registered_or_refused(scene, frames, ev, seed):
    """Generated hand-held JPEG ladders (:func:`tests.hard_cases.hand_held_walkers`
    without the figure): every bracket registered within 0.5 px of its true warp at the
    corners, or refused (merged only where no registered bracket sees the scene), never
    merged misregistered. Before the misfits of a warp and of no motion were compared on
    the same points: Desk's middle bracket of three refused ('fits the fine level only',
    0.102 against 0.065: no motion kept the easier points), StillLife's five registered
    up to 2.3, 5.6 and 9.1 px off (seeds 0-2). Measured: 0.26 px; 0.13 and 0.34 px
    with the longest refused.

    GoldenGate's 7-bracket ladder was registered 5.9 and 9.1 px off (seeds 1, 2): true
    shifts of 1-2 px judged "no motion" on two thirds of a 200 x 300 base (its smooth sky
    fits any shift alike; the judge now reads the strongest tenth,
    :data:`hdrio.align.registration.JUDGE_SHARE`), and a 9 px shift that Lucas-Kanade
    did not reach from the bitmaps' guess (it does from the masked correlation's,
    :func:`hdrio.align.correlation.masked_ncc_shift`). Measured now: 0.10 and 0.44 px,
    the longest two refused."""
    case = hand_held_walkers(scene, frames, ev, seed, figure=False)
    result = merge_stack(case.stack(), MergeOptions(deghost="off"))
    alignment = result.motion.alignment
    refused = {j for j, _ in alignment.refused}
    errors = [e for j, e in enumerate(case.corner_errors(alignment)) if j not in refused]
    assert max(errors) < 0.5, (errors, alignment.refused)
    if scene == "Desk":
        assert not refused, alignment.refused


STILL_STACKS = {
    "tripod-jpeg": lambda: tripod_stack("jpeg"), "tripod-png": lambda: tripod_stack("png"),
    "tripod-16bit": lambda: tripod_stack("16-bit"),
    "tripod-16bit-stilllife": lambda: tripod_stack("16-bit", scene="StillLife"),
    "night-jpeg": lambda: night_stack(0, "jpeg"), "night-png": lambda: night_stack(0, "png"),
    "night-png-1": lambda: night_stack(1, "png"),
    "tripod-mttam": lambda: movers(crossing=0, scene="MtTamWest"),
    "linear-stilllife-5x1": lambda: linear_still_life(0, 0, 5, 1.0, 1)[0]}
"""Still stacks of the generator. The 16-bit StillLife ladder and the second night
stack were warped (0.22-0.29 px, then 20 % deghosted; 1.6 px) until a clipped highlight's
shift near none stopped counting as agreement with a warp the edges could not judge; the
linear 5 x 1 EV StillLife ladder's shortest bracket (0.36 px) until a highlight shift the
centroids could not refine counted as motion only above its precision (UNREFINED)."""


@pytest.mark.parametrize("name", sorted(STILL_STACKS))
def test_still_generated_stacks_are_left_alone(name):
    """Every still stack of the generator: nothing warped, nothing deghosted, and the
    pixels bit-identical to --align off --deghost off."""
    stack = STILL_STACKS[name]().stack()
    auto = merge_stack(stack, MergeOptions())
    off = merge_stack(stack, MergeOptions(align="off", deghost="off"))
    assert not auto.motion.warped and auto.motion.deghosting.fraction == 0.0
    assert np.array_equal(auto.radiance, off.radiance)


@pytest.mark.parametrize("name", ["tripod-16bit-stilllife", "night-png-1"])
def test_registration_leaves_a_still_generated_stack_still(name, monkeypatch):
    """The same stacks registered in full (the still check made to give up, as it does on
    stacks it cannot settle): every bracket within auto's 0.1 px, nothing warped. The
    darkest frames' edges (noise alone) preferred a warp that fitted no better than none;
    the shift of the highlights their neighbour clipped, near none, was taken as
    agreeing with it (within CLIP_AGREE), and the frames were warped by 0.22-0.29 px
    (StillLife, then 20 % deghosted) and 1.6 px (the night stack). A highlight shift now
    agrees with a warp only where it is nearer that warp than no motion."""
    import hdrio.align.motion as stage

    looks_still = stage.looks_still
    monkeypatch.setattr(stage, "looks_still",
                        lambda *args, **kwargs: (False, looks_still(*args, **kwargs)[1]))
    stack = STILL_STACKS[name]().stack()
    result = merge_stack(stack, MergeOptions())
    assert max(result.motion.alignment.motion) < 0.1, result.motion.alignment.motion
    assert not result.motion.warped


def test_a_response_is_not_re_solved_across_a_gap_registration_leaves(monkeypatch):
    """A still linear 16-bit StillLife ladder whose middle bracket registration refuses
    (too few edges well exposed in both: here the well-exposed codes are 5-95 % of the
    linear range, a 4.3-stop window, as they were before deep codes' window was set in
    light; with that window the still check settles the stack) and whose short brackets
    it warps by their highlights' shift (as on a hand-held stack: here, with UNREFINED
    0, by the unrefined shift of 0.15-0.29 px that it now takes as no motion). Its
    re-solve sampled the brackets 16 and 256 times the shortest side by side, with no
    bracket between them: the green and blue curves came out with 3.4 times the true log
    range, and the merge was 78 % off at the median, against 0.8 % with --align off.
    Such a sample is not solved on (hdrio.align.resolve.unlinked): the response solved
    as read is kept. Bound: 2x the --align off merge's median error (measured 1.16 %
    against 0.78 %: the warped brackets are resampled)."""
    import hdrio.align.registration as registration
    from hdrio.tools.synthetic import radiance_error, well_exposed

    monkeypatch.setattr(registration, "UNREFINED", 0.0)
    for module in ("hdrio.align.registration", "hdrio.align.pyramid", "hdrio.align.quick",
                   "hdrio.align.resolve"):  # the window of the code fractions alone
        monkeypatch.setattr(f"{module}.well_exposed_codes",
                            lambda code_max, fractions=WELL_EXPOSED, linear=None:
                            well_exposed_codes(code_max, fractions))
    case, scene = linear_still_life(40, 30)
    stack = case.stack()
    inner = np.zeros(case.codes.shape[1:3], bool)
    inner[16:-16, 16:-16] = True
    inner &= well_exposed(case.codes, case.camera.code_max)
    auto = merge_stack(stack, MergeOptions())
    off = merge_stack(stack, MergeOptions(align="off", deghost="off"))
    errors = [radiance_error(r.radiance, scene, inner)["median"] for r in (auto, off)]
    assert errors[0] < 2 * errors[1], errors
    assert auto.motion.warped  # the re-solve ran on a warped stack
    g, first = auto.response.log_inverse, off.response.log_inverse
    span, truth = g[60000] - g[100], first[60000] - first[100]
    assert np.allclose(span, truth, rtol=0.05), (span, truth)


def test_unlinked_tests_only_neighbours_a_refused_bracket_stood_between():
    """Two brackets of an aligned sample well exposed together at no point: a gap where
    a refused bracket stood between them (kept 0 and 2), nothing to test where they are
    neighbours in the stack (kept 0 and 1); and linked at LINK_POINTS points."""
    from hdrio.align.resolve import LINK_POINTS, unlinked

    codes = np.zeros((2, 20, 20, 3), np.uint8)
    codes[0, :10] = 128  # each well exposed on its own half only
    codes[1, 10:] = 128
    uncovered = np.zeros((20, 20), bool)
    assert unlinked(codes, 255, uncovered, [0, 2]) == 0
    assert unlinked(codes, 255, uncovered, [0, 1]) is None
    codes = np.zeros((2, 1, LINK_POINTS + 1, 3), np.uint8)
    codes[:, :, :LINK_POINTS] = 128
    assert unlinked(codes, 255, np.zeros((1, LINK_POINTS + 1), bool), [0, 2]) is None
    codes[:, :, 0] = 0
    assert unlinked(codes, 255, np.zeros((1, LINK_POINTS + 1), bool), [0, 2]) == 0


def test_a_hand_held_ladder_registers_its_darkest_bracket():
    """A hand-held 7 x 2 EV ladder of a scene with a sun, every bracket moved by up to
    6 px and 0.3 deg. The shortest bracket, which alone sees the sun's disc, is now
    registered through its neighbour at codes from 2 % of the range (it was 'not
    registered: only 0.0 % ... unclipped'). The second longest, 98 % clipped, is
    registered from the masked correlation's start (the bitmaps put it 15 px off, and it
    was refused: 'too few well-exposed edges in common'); the longest, 100 % clipped, is
    not, and is merged only where no registered bracket sees the scene (flagged in the
    motion layer and the header). Measured against the same stack held still, in the
    reference's frame: median 1.29x, p99 2.22x (the issue's bounds 1.3x and 2x; p99 not
    met, the sun's edge and the city lights: 2.21x with the true warps); 1.31x and 2.28x
    with the second longest refused; 1.67x and 2.44x until the re-solve's sample was
    blurred alike; 5.65x and 6.91x before the shortest was registered.
    Bounds here: every registered bracket within 0.2 px of its true warp at the corners
    (measured 0.03-0.14 px), median 2x and p99 3x."""
    from hdrio.job.output import exr_attributes

    moving, held = hand_held(7, 0), hand_held(7, 0, still=True)
    result = merge_stack(moving.stack(), MergeOptions())
    still = merge_stack(held.stack(), MergeOptions())
    alignment = result.motion.alignment
    refused = {j for j, _ in alignment.refused}
    assert refused == {6}, alignment.refused
    height, width = moving.codes.shape[1:3]
    for j, error in enumerate(moving.corner_errors(alignment)):
        assert j in refused or error < 0.2, (j, error)
    header = exr_attributes(result)
    assert len(header["hdrio:alignUnregistered"]) == len(refused)
    truth = moving.truth_in(alignment.reference)
    inner = np.zeros((height, width), bool)
    inner[16:-16, 16:-16] = True
    inner &= well_exposed(held.codes, 255)
    moved = radiance_error(result.radiance, truth, inner)
    base = radiance_error(still.radiance, held.truth_in(alignment.reference), inner)
    assert moved["median"] < 2 * base["median"] and moved["p99"] < 3 * base["p99"], (
        moved, base)


def test_one_rule_for_the_reference_everywhere(capsys, tmp_path, write_brackets):
    """README, --align's help and the summary say which bracket is the reference in the
    same words (README and help said 'best-exposed' while the summary picked the longest
    well-exposed one)."""
    from pathlib import Path

    from hdrio.align import REFERENCE_RULE
    from tests.conftest import run_cli

    readme = (Path(__file__).parents[1] / "README.md").read_text()
    assert " ".join(REFERENCE_RULE.split()) in " ".join(readme.split())
    code, out, _ = run_cli(capsys, "merge", "--help")
    assert " ".join(REFERENCE_RULE.split()) in " ".join(out.split())
    paths = write_brackets()
    code, out, err = run_cli(capsys, "merge", *paths, "-o", tmp_path / "o.exr")
    assert code == 0, err
    assert f"({REFERENCE_RULE})" in out


@pytest.mark.parametrize("count", [5, 7, 9])
def test_the_speed_scene_as_jpeg_is_left_alone(count, tmp_path):
    """The speed benchmark's still scene at 5, 7 and 9 brackets 2 EV apart, written as
    the benchmark writes it (JPEG quality 95), merged from the files with the defaults:
    nothing deghosted, pixels identical to --deghost off. Codes just short of the clip
    read as exact estimates flagged its windows' JPEG-bent edges (2-6 % deghosted, 27 s
    of deghosting at 24 MP) until the test read them as bounds."""
    from benchmarks.speed.endtoend import write_jpegs
    from benchmarks.speed.scene import bracket_stack
    from hdrio.job.run import merge_paths

    stack, _ = bracket_stack(600, 900, count)
    paths = write_jpegs(stack, tmp_path)
    exposures = [repr(float(t)) for t in stack.exposures]
    auto = merge_paths(paths, exposures=exposures)
    off = merge_paths(paths, exposures=exposures, options=MergeOptions(deghost="off"))
    assert auto.motion.deghosting.fraction == 0.0
    assert np.array_equal(auto.radiance, off.radiance)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_hand_held_ladders_exposures_are_measured_on_its_registered_brackets(seed):
    """The exposure check compares brackets pixel by pixel; before registration a
    hand-held ladder's pixels are different scene points. Measured there, the check
    named 3-5 brackets of every 7-bracket ladder (up to 3.5 stops "off"; their exposures
    are exact), and ``--exposures-from-data`` failed ("same exposure ..."). Now the check
    runs on the registered brackets, the ones that could not be registered keep their
    metadata (``unmeasured``, in the header), and ``--exposures-from-data`` fits the
    exposures with alignment's re-solved response. Bounds: no warning; the fitted
    exposures within 0.01 stop of the true ones (measured 0.0005 and 0.0011 stop, seeds
    0 and 1; 0.0014 and 0.0097 until the re-solve's sample was blurred alike: the fit of
    bracket 5, clipped at 98 % of its pixels, read sharp codes beside its clipped
    ones); the merge with them within 5 % of the default's median error (measured
    1.313 against 1.315 and 1.293 against 1.299, in units of the still stack's)."""
    from hdrio.job.output import exr_attributes

    moving = hand_held(7, seed)
    checked = merge_stack(moving.stack(), MergeOptions())
    used = merge_stack(moving.stack(), MergeOptions(exposures_from_data=True))
    refused = tuple(sorted(j for j, _ in checked.motion.alignment.refused))
    assert checked.motion.warped and refused
    assert checked.exposures.warnings("explicit") == []
    assert checked.exposures.unmeasured == refused == used.exposures.unmeasured
    assert exr_attributes(checked)["hdrio:exposuresUnmeasured"] == [
        f"{moving.name}_{j}.png" for j in refused]
    stops = np.log2(used.exposures.estimated / moving.exposures)
    assert used.exposures.used and np.max(np.abs(stops)) < 0.01, stops
    reference = checked.motion.alignment.reference
    truth = moving.truth_in(reference)
    inner = np.zeros(moving.codes.shape[1:3], bool)
    inner[16:-16, 16:-16] = True
    inner &= well_exposed(moving.codes, 255)
    default = radiance_error(checked.radiance, truth, inner)["median"]
    assert radiance_error(used.radiance, truth, inner)["median"] < 1.05 * default


@pytest.mark.parametrize("seed", [0, 1])
def test_a_hand_held_ladder_without_metadata_is_inferred_on_its_registered_brackets(
        seed, tmp_path, capsys):
    """``--exposures-from-data`` with no metadata at all, on a hand-held ladder (PNGs: no
    EXIF). The inference compared brackets that had moved, and failed ("same exposure
    (0.31) as b0.png (1)", two different exposures; seeds 0-3). Now, where it fails, the
    brackets are registered with provisional exposures and the ladder is inferred on
    alignment's aligned sample; the
    brackets that could not be registered are placed by the step, said in the summary
    and the header. Bounds: every bracket within 0.05 stop of the truth, relative to the
    middle one (measured: 0.017 the shortest, which sees only the sun, 0.006 the placed
    ones; 0.13 and 0.034 until the aligned sample was blurred alike); the merge's median
    error within 1.15x that of the same files merged with their true exposures (measured
    1.01x and 0.93x for seeds 0 and 1; 1.24x and 0.99x before)."""
    import OpenImageIO as oiio

    from hdrio.job.run import merge_paths
    from tests.conftest import run_cli

    case = hand_held(7, seed)
    paths = [tmp_path / f"b{j}.png" for j in range(7)]
    for path, codes in zip(paths, case.codes, strict=True):
        assert oiio.ImageBuf(np.ascontiguousarray(codes)).write(str(path), "uint8")
    output = tmp_path / "out.exr"
    code, out, err = run_cli(capsys, "merge", *paths, "--exposures-from-data", "-o", output)
    assert code == 0, err
    spec = oiio.ImageInput.open(str(output)).spec()
    unmeasured = list(spec.getattribute("hdrio:exposuresUnmeasured"))
    assert unmeasured and f"{', '.join(unmeasured)} not registered: placed by the step" in out
    used = np.array(spec.getattribute("hdrio:exposures"), float)
    stops = np.log2(used / used[3]) - np.log2(case.exposures / case.exposures[3])
    assert np.max(np.abs(stops)) < 0.05, stops
    inferred = merge_paths(paths, options=MergeOptions(exposures_from_data=True))
    known = merge_stack(case.stack(), MergeOptions())
    reference = known.motion.alignment.reference
    assert inferred.motion.alignment.reference == reference
    radiance = inferred.radiance
    truth = case.truth_in(reference)
    inner = np.zeros(case.codes.shape[1:3], bool)
    inner[16:-16, 16:-16] = True
    inner &= well_exposed(case.codes, 255)
    assert radiance_error(radiance, truth, inner)["median"] < 1.15 * radiance_error(
        known.radiance, truth, inner)["median"]


@pytest.mark.parametrize("seed", [0, 3])
def test_a_warm_ladders_long_brackets_are_registered_by_the_channel_they_clip_least(seed):
    """StillLife's 7 x 2 EV hand-held JPEG ladder (:func:`tests.hard_cases.hand_held_walkers`
    without the figure): its reference is the longest bracket, red clipped over 74 % of
    it. The bitmaps' start for its neighbours sits in the clip (15-30 px off), the
    masked correlation finds nothing, and the neighbour's one good warp (0.3 px off)
    was refused, too few well-exposed edges in common to judge it: the next bracket,
    4 EV from the reference, was judged "no motion", and every shorter one followed it,
    3.3-5.3 px off (seeds 0, 1, 3). Now a shorter bracket also starts from the shift of
    the highlights its longer neighbour clipped in the channel it clips least (blue
    here, :func:`hdrio.align.highlight_shift.channel_clip_regions`), that shift itself is
    a candidate, a warp the edges cannot judge is taken where that shift agrees with it,
    and the best warp is polished on the judge's misfit (Lucas-Kanade walked 1-10 px off
    a good start on the dark second shortest bracket). Measured, seeds 0 and 3: every
    bracket registered, brackets 2-5 within 0.33-0.58 px (0.33-0.90 without the polish),
    the two darkest (well exposed at 16 % of their pixels) 0.53-0.57 and 0.96-1.00 px
    (1.0 and 1.8 without). Bounds: 0.75 px for brackets 2-6, 1.5 px for all; the issue's
    0.5 px is not met everywhere (seed 1: 0.92 px)."""
    case = hand_held_walkers("StillLife", 7, 2.0, seed, figure=False)
    alignment = merge_stack(case.stack(), MergeOptions(deghost="off")).motion.alignment
    errors = case.corner_errors(alignment)
    assert alignment.reference == 6 and not alignment.refused, alignment.refused
    assert max(errors[2:]) < 0.75 and max(errors) < 1.5, errors


def test_channel_clip_regions_read_the_channel_clipped_least():
    """:func:`hdrio.align.highlight_shift.channel_clip_regions` on a warm scene: red
    clipped nearly everywhere in the longer bracket, blue in a disc. The blue regions,
    the shorter bracket's as many brightest pixels as the longer clipped (whatever its
    curve); :func:`hdrio.align.highlight_shift.highlight_shift` on them finds the shift
    (within 0.25 px). ``None`` when no channel is clipped at 16 base pixels."""
    from hdrio.align.highlight_shift import channel_clip_regions, highlight_shift

    yy, xx = np.mgrid[0:120, 0:160].astype(float)

    def view(cx, cy, gain):
        blue = 60.0 + 200.0 * np.exp(-0.5 * (np.hypot(xx - cx, yy - cy) / 9.0) ** 2)
        red = np.full_like(blue, 400.0)
        return np.clip(np.stack([red, 0.6 * blue, blue], axis=-1) * gain, 0, 255).astype(np.uint8)

    longer, shorter = view(80.0, 60.0, 1.0), view(83.0, 58.0, 0.25)
    regions = channel_clip_regions(longer, shorter, 242, 1)
    assert regions is not None
    clipped, bright = regions
    assert clipped.sum() == np.count_nonzero(longer[..., 2] >= 242) < 0.1 * clipped.size
    shift = highlight_shift(clipped, bright)
    assert shift is not None and abs(shift[0, 2] - 3.0) < 0.25 and abs(shift[1, 2] + 2.0) < 0.25
    assert channel_clip_regions(shorter, shorter, 242, 1) is None


@pytest.mark.parametrize("seed", [0, 1, 5])
def test_a_nine_bracket_hand_held_ladder_is_registered_or_refused(seed):
    """``hand_held(9, seed)``: 9 x 2 EV, every bracket moved by up to 6 px and 0.3 deg.
    The first pass, with a response solved on the moved brackets, put its short brackets
    5-10 px off; the second, with the response re-solved on the aligned sample, only
    refined the base level from there and left brackets 1 and 2 of seed 1 4.35 and 4.37 px
    off, registered. Measured afresh it finds them within 0.1 px (measured 0.03-0.14 px
    for every registered bracket of both seeds). Bound: the issue's 0.5 px.

    A bracket is refused only for having too little usable in common with its neighbour
    (the shortest and the two longest), never for its evidence: bracket 3 of seed 5,
    measured 0.02 px from its true warp, was refused as "the shift fits the fine level
    only" while the alias test compared misfits on all of the coarsest level's points,
    60 % of them a smooth sky (:data:`hdrio.align.registration.COARSE_SHARE`)."""
    case = hand_held(9, seed)
    alignment = merge_stack(case.stack(), MergeOptions()).motion.alignment
    refused = {j for j, _ in alignment.refused}
    errors = [e for j, e in enumerate(case.corner_errors(alignment))
              if j not in refused and j not in alignment.by_highlights]
    assert len(errors) >= 5 and max(errors) < 0.5, (errors, alignment.refused)
    assert all(why.startswith("only ") for _, why in alignment.refused), alignment.refused


@pytest.mark.parametrize("seed", [1, 3, 4])
def test_a_ladders_shortest_bracket_is_registered_on_its_sun(seed):
    """``hand_held(9, seed)``: the shortest bracket sees only the sun (0.4 % of it usable
    where its neighbour is, 0.5 % needed), and was left unwarped, 3-6 px off. Deghosting
    then dropped it as moving where its displaced disc showed sky inside the true sun
    (5.5-5.9 % of a still scene "deghosted"), and the sun's 60 brightest pixels came out
    at 0.092 and 0.007 of the truth. Now it is registered by the sun its neighbour
    clipped (:mod:`hdrio.align.highlight_shift`), nothing deghosted, the sun at 0.86-0.90
    of the truth (the still stack's merge: 0.91), said in the summary and the header.
    At the sun's brightest pixel the masks' correlation alone left it 0.15, 0.05 and 0.16
    px off; refined by the highlights' centroids, 0.050, 0.037 and 0.028 px. Bounds: 0.1
    px at the sun; 0.7-1.3."""
    from hdrio.job.output import exr_attributes

    case = hand_held(9, seed)
    result = merge_stack(case.stack(), MergeOptions())
    alignment = result.motion.alignment
    assert alignment.by_highlights == (0,) and 0 not in dict(alignment.refused)
    truth = case.truth_in(alignment.reference)
    brightness = truth.mean(axis=-1)
    y, x = np.unravel_index(int(np.argmax(brightness)), brightness.shape)
    true = case.warps[0] @ np.linalg.inv(case.warps[alignment.reference])
    measured, expected = alignment.transforms[0] @ [x, y, 1.0], true @ [x, y, 1.0]
    assert np.hypot(*(measured[:2] / measured[2] - expected[:2] / expected[2])) < 0.1
    assert result.motion.deghosting.fraction == 0.0
    radiance = result.radiance.astype(np.float64)
    scale = np.exp(np.median(np.log(truth / np.maximum(radiance, 1e-12))))
    sun = brightness > np.percentile(brightness, 99.9)
    assert 0.7 < np.median((scale * radiance / truth).mean(axis=-1)[sun]) < 1.3
    assert exr_attributes(result)["hdrio:alignByHighlights"] == [result.stack.files[0]]
    lines = alignment.describe(result.stack.files)  # the summary's align: lines
    assert "by the highlights its neighbour clipped" in lines[0], lines


@pytest.mark.parametrize("frames,seed", [(7, 2), (7, 4), (7, 5), (7, 14), (7, 19), (9, 1),
                                         (9, 5)])
def test_a_hand_held_ladders_median_error_is_within_the_issues_bound(frames, seed):
    """``hand_held(frames, seed)`` against the same stack held still, in the reference's
    frame: median error at most 1.3x (issue 28).

    - The response re-solved after the warp bent at both ends while the reference was
      sharp and the warped brackets blurred by their interpolation (the sampler picks a
      texture's darkest and brightest codes, where a blurred bracket reads nearer the
      mean): 1.34, 1.35 and 1.58x for seeds 2, 4 and 5; every bracket is now sampled
      through the same 3x3 binomial (:func:`hdrio.align.resolve.sampled_stack`):
      1.22, 1.22 and 1.22x.
    - The response was re-solved once, on the first pass's alignment, and the merge
      read it whatever the second pass found: seed 19's first pass put brackets 0 and 1
      9.7 px off (its curve up to 0.018 r.m.s. from the truth, the still stack's 0.007), and
      its merge was 1.70x; seed 14's, 1.48x; the 9-bracket ladders' 2.05 and 3.59x (a
      blue wave). It is now solved again until the alignment it gives agrees with the
      one it was solved on (:data:`hdrio.align.registration.RESOLVES`): 1.22, 1.23,
      1.22 and 1.17x.

    ``hand_held(7)`` over seeds 0-19: 1.19-1.31x (seed 7, 1.31x, is at its floor: 1.31x
    with the true warps). The issue's p99 bound, 2x, is not met (1.93-2.41x; seeds 0-9
    with the true warps 1.92-2.21x: the sun's edge and the city lights)."""
    moving, held = hand_held(frames, seed), hand_held(frames, seed, still=True)
    result = merge_stack(moving.stack(), MergeOptions())
    still = merge_stack(held.stack(), MergeOptions())
    reference = result.motion.alignment.reference
    height, width = moving.codes.shape[1:3]
    inner = np.zeros((height, width), bool)
    inner[16:-16, 16:-16] = True
    inner &= well_exposed(held.codes, 255)
    moved = radiance_error(result.radiance, moving.truth_in(reference), inner)["median"]
    base = radiance_error(still.radiance, held.truth_in(reference), inner)["median"]
    assert moved <= 1.3 * base, moved / base


def test_the_hand_held_benchmark_measures_against_the_still_stack_and_the_true_warps():
    """``python -m benchmarks.hand_held``'s rows (docs/motion.md's tables), seed 2: the
    measured warps' row (median 1.22x the still stack's, the worst registered bracket
    0.39 px off) and the oracle's with the true warps (0 px by construction; median
    1.21x: resampling alone); and a row of ``--registration``. Bounds: the issue's 1.3x
    for the medians, registration within 0.5 px, and the oracle's warps exact."""
    from benchmarks.hand_held import measure, registration, seeds_of

    assert seeds_of("0-3") == [0, 1, 2, 3] and seeds_of("1,5") == [1, 5]
    measured, oracle = measure(7, 2, False), measure(7, 2, True)
    assert measured["refused"] == oracle["refused"] == [6]
    assert measured["worst_px"] < 0.5 and oracle["worst_px"] < 1e-9
    assert measured["median"] <= 1.3 and oracle["median"] <= 1.3, (measured, oracle)
    # --registration's row for GoldenGate's 7-bracket walker ladder, seed 2 (9.14 px off
    # at 89e8d38; measured 0.44 px, the two longest refused).
    row, = registration([2], ladders=(("GoldenGate", 7),))
    assert row["worst_px"] < 0.5 and row["refused"] == [5, 6], row


@pytest.mark.parametrize("frames,seed", [(7, 2), (7, 5), (9, 4)])
def test_a_hand_held_ladder_through_a_lens_is_within_both_of_the_issues_bounds(frames, seed):
    """``hand_held(frames, seed, lens=0.5)``: the same ladder with every view blurred by a
    Gaussian point spread of 0.5 px before capture, as a lens and an anti-aliasing filter
    blur what reaches a sensor (the generator's default has none, and its edges are
    sharper than any lens gives: there resampling alone costs p99 1.92-2.21x the still
    stack's). Against the same stack held still (through the same lens): median at most
    1.3x and p99 at most 2x, the issue's bounds. Measured: 1.05x / 1.74x, 1.04x / 1.75x
    and 1.07x / 1.75x (`python -m benchmarks.hand_held --lens 0.5`, seeds 0-19: medians
    1.04-1.15x, p99 1.74-2.12x, 19 of 20 within 2x; ``--frames 9``, seeds 0-9: medians
    1.03-1.11x, p99 1.71-1.98x, 10 of 10). ``hand_held(9, 4)`` was at p99 2.10x while its
    shortest bracket, registered by its sun alone, sat 0.19 px off there (the masks'
    correlation; 0.03 px refined by the sun's centroid,
    :func:`hdrio.align.highlight_shift.refine_by_centroids`)."""
    from benchmarks.hand_held import measure

    row = measure(frames, seed, False, lens=0.5)
    assert row["median"] <= 1.3 and row["p99"] <= 2.0, row
