"""The Blender extension's pure-Python parts (no ``bpy``): run in the main suite too."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hdrio.errors import InputError
from hdrio.io.brackets import read_brackets
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_stack
from hdrio.merge.saturation import ClipPolicy
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import NoiseModel
from plugins.blender.baking import (
    CURVE_TABLE_SIZE,
    bake_merge,
    response_from_json,
    response_to_json,
    scene_linear_response,
    table_squeeze,
)
from plugins.blender.build import extension_files, manifest_fields, manifest_text
from plugins.blender.exposures import (
    PLACEHOLDER,
    TYPED,
    edited_sources,
    exposure_state,
    exposures_for_files,
    input_problems,
    placeholder_brackets,
    sorted_order,
)
from plugins.blender.warmup import KernelWarmup

REPOSITORY = Path(__file__).resolve().parents[3]


def smooth_response(code_max: int = 255, channels: int = 3) -> CameraResponse:
    """A gamma-like response with a tint per channel and unsupported ends."""
    z = np.maximum(np.arange(code_max + 1, dtype=np.float64), 0.5) / code_max
    g = np.stack([(2.0 + 0.2 * c) * np.log(z) for c in range(channels)], axis=1)
    supported = np.zeros_like(g, dtype=bool)
    supported[code_max // 20: code_max - code_max // 50] = True
    return CameraResponse(g, code_max, supported)


def node_merge(codes: np.ndarray, baked) -> np.ndarray:
    """The HDR Merge node's graph (merge_graph.py) in NumPy, on 8-bit codes ``(P, H, W,
    3)`` shortest first: float32 curves mapped back, the core's saturation policy as the
    node applies it (limits, whole observations: the pixel rule or the clip test),
    fallback, neutral lower bound, exp.

    The curves hold a point at every code, which the node evaluates exactly (the bpy
    tests measure that); this checks that the tables and the policy are hdrio's merge.
    """
    P = codes.shape[0]
    channel = np.arange(3)
    policy = baked.policy
    z = codes.astype(np.float32) / baked.code_max  # the node reads codes as [0, 1]

    def table(curves, j):
        values = (curves.curves.astype(np.float32)[j][codes[j], channel]
                  * np.float32(curves.span[j]) + np.float32(curves.low[j]))
        return values.astype(np.float32)

    clipped = z > baked.level(policy.limits).astype(np.float32)
    gates = policy.limits if policy.gates is None else policy.gates
    near = z > baked.level(gates).astype(np.float32)
    saturated = clipped.copy()
    if policy.rule == "pixel":
        saturated |= clipped.any(axis=-1, keepdims=True)
    elif policy.rule == "test":
        saturated[0] |= clipped[0].any(axis=-1, keepdims=True) & policy.neutral
        tables = baked.estimates if not baked.log_domain else baked.clip_estimates
        for j in range(1, P):
            d = table(tables, j) - table(tables, j - 1)
            v = table(baked.clip_deviations, j) ** 2 + table(baked.clip_deviations, j - 1) ** 2
            spread = np.ones(3) if policy.spreads is None else policy.spreads[j]
            fails = d * d > v * ((policy.tables.sigmas * spread) ** 2).astype(np.float32)
            beyond = z[j - 1] > baked.level(baked.reach(j)).astype(np.float32)
            flags = ~clipped[j] & (clipped[j - 1] | fails | beyond)
            whole = near[j].any(axis=-1, keepdims=True) & flags.any(axis=-1, keepdims=True)
            # Below its limit where the shorter bracket is at it: dropped wherever it is.
            whole |= (~clipped[j] & clipped[j - 1]).any(axis=-1, keepdims=True)
            saturated[j] |= whole
    dropped = np.maximum.accumulate(saturated, axis=0)
    numerator = np.zeros(codes.shape[1:], np.float32)
    denominator = np.zeros(codes.shape[1:], np.float32)
    fallback = table(baked.estimates, 0)
    for j in range(P):
        keep = ~dropped[j]
        weight = table(baked.weights, j) * keep
        estimate = table(baked.estimates, j)
        numerator += weight * estimate
        denominator += weight
        fallback = np.where(keep, estimate, fallback)
    merged = np.where(denominator > 0, numerator / np.maximum(denominator, 1e-30), fallback)
    # Clipped in every bracket (every channel, or dropped whole there): neutral.
    everywhere = saturated[0].all(axis=-1)
    neutral = table(baked.estimates, 0).max(axis=-1)
    merged = np.where(everywhere[..., None], neutral[..., None], merged)
    return np.exp(merged) if baked.log_domain else merged


def assert_node_is_hdrio_merge(label, codes, exposures, result):
    # hdrio merge's defaults (MergeOptions()), with the noise model the merge fitted and
    # the saturation policy it decided on the stack (what a Solve stores on the node).
    baked = bake_merge(result.response, exposures, noise=result.noise,
                       policy=result.statistics.policy)
    difference = np.abs(node_merge(codes, baked) / result.radiance - 1.0)
    print(f"{label}: median {np.median(difference):.1e} "
          f"p99 {np.percentile(difference, 99):.1e} max {difference.max():.1e}")
    # float32 curves (2^-24 relative of each table's span) and float32 sums against the
    # kernel's complex64 sums: measured max 2e-6; 1e-5 still fails on a wrong weight,
    # domain, bracket order or dropped observation (percent-level differences).
    assert difference.max() <= 1e-5


@pytest.mark.slow
def test_baked_tables_are_hdrio_default_merge_on_synthetic_brackets(write_brackets):
    paths = write_brackets((1 / 16, 1 / 4, 1.0, 4.0), size=(40, 96))
    stack = read_brackets(paths)
    result = merge_stack(stack, MergeOptions())
    assert_node_is_hdrio_merge("synthetic", stack.codes, stack.exposures, result)


def test_baked_tables_are_hdrio_default_merge_on_frobisher(shared_data):
    paths = sorted(shared_data("frobisher_001").glob("*.jpg"))
    stack = read_brackets(paths)
    result = merge_stack(stack, MergeOptions())
    assert not np.all(result.response.supported[1:-1])  # single codes without weight
    policy = result.statistics.policy
    assert policy.rule == "test" and policy.neutral  # a 5D Mark II mixes after the clip
    assert_node_is_hdrio_merge("frobisher", stack.codes, stack.exposures, result)


@pytest.mark.parametrize("merge, saturation", [("log", "channel"), ("linear", "channel"),
                                               ("log", "pixel"), ("Poisson", "channel"),
                                               ("inverse-variance", "pixel"),
                                               ("log", "auto"), ("linear", "safe")])
def test_baked_tables_follow_the_options(write_brackets, merge, saturation):
    paths = write_brackets((1 / 16, 1 / 4, 1.0, 4.0), size=(40, 96))
    stack = read_brackets(paths)
    options = MergeOptions(merge=merge, saturation=saturation)
    result = merge_stack(stack, options)
    policy = result.statistics.policy
    baked = bake_merge(result.response, stack.exposures, options, noise=result.noise,
                       policy=policy)
    assert baked.log_domain == (merge == "log")
    assert baked.policy.rule == {"channel": "channel", "pixel": "pixel", "safe": "pixel",
                                 "auto": "test"}[saturation]
    difference = np.abs(node_merge(stack.codes, baked) / result.radiance - 1.0)
    assert difference.max() <= 1e-5  # as above


def test_unsolved_node_drops_whole_observations_at_the_top_code():
    # No Solve, no stack to find white levels in: the top code, the pixel rule (the
    # channel rule where the options say so).
    baked = bake_merge(smooth_response(), [1.0, 4.0])
    assert baked.policy.rule == "pixel" and list(baked.policy.limits) == [255] * 3
    channel = bake_merge(smooth_response(), [1.0, 4.0], MergeOptions(saturation="channel"))
    assert channel.policy.rule == "channel"


def test_curves_are_in_unit_range_and_map_back():
    baked = bake_merge(smooth_response(), [1 / 16, 1.0, 8.0], MergeOptions(merge="log"))
    for table in (baked.weights, baked.estimates):
        assert table.curves.shape == (3, 256, 3)
        assert table.curves.min() >= 0.0 and table.curves.max() <= 1.0
    assert np.all(baked.weights.values()[:, -1] == 0)  # saturated codes never count
    # Estimates in the log domain: g - ln dt, per bracket (float64 round trip, 1e-12).
    g = smooth_response().log_inverse
    np.testing.assert_allclose(baked.estimates.values()[2], g - np.log(8.0), atol=1e-12)


def test_16bit_response_is_sampled_at_256_codes_and_grey_fills_rgb():
    baked = bake_merge(smooth_response(code_max=65535, channels=1), [0.5, 2.0])
    codes = np.rint(baked.positions * 65535).astype(int)
    assert codes.size == 256 and codes[0] == 0 and codes[-1] == 65535
    assert baked.estimates.curves.shape == (2, 256, 3)
    assert np.array_equal(baked.estimates.curves[..., 0], baked.estimates.curves[..., 2])
    assert baked.level(baked.policy.limits)[0] == pytest.approx(65534.5 / 65535)


def test_bake_refuses_degenerate_input():
    with pytest.raises(ValueError, match="at least 2 points"):
        bake_merge(smooth_response(), [1.0, 2.0], points=1)
    with pytest.raises(ValueError, match="shortest first"):
        bake_merge(smooth_response(), [2.0, 1.0])
    response = smooth_response()
    unsupported = response.supported.copy()
    unsupported[:, 1] = False
    with pytest.raises(ValueError, match="no supported code value"):
        bake_merge(CameraResponse(response.log_inverse, 255, unsupported), [1.0, 2.0])


def test_scene_linear_response_gives_a_pass_back_at_its_scale():
    # A render pass (scene-linear, exposure 1) merged with itself: E = z, not 255/128 z.
    baked = bake_merge(scene_linear_response(), [1.0, 1.0], MergeOptions())
    z = np.arange(256)
    codes = np.stack([z, z])[:, :, None, None].repeat(3, axis=-1)[:, :, 0]  # (2, 256, 3)
    merged = node_merge(codes[:, :, None, :], baked)[:, 0, 1]
    # Codes 1..254 carry weight: float32 curves, rounding only.
    np.testing.assert_allclose(merged[1:-1], z[1:-1] / 255, rtol=1e-6)


def test_response_json_round_trip():
    response = smooth_response()
    solved = response_from_json(response_to_json(response, "from test"))
    again = solved.response
    assert np.array_equal(again.log_inverse, response.log_inverse)
    assert np.array_equal(again.supported, response.supported)
    assert (again.code_max, again.method, solved.label, solved.noise, solved.policy) == (
        255, response.method, "from test", None, None)
    fitted = NoiseModel(np.array([1e-4, 2e-4, 3e-4]), np.array([1e-7, 0.0, 2e-7]),
                        np.array([1 / 12, 0.5, 4.0]), "fitted")
    policy = ClipPolicy(np.array([250, 252, 254]), np.array([240, 245, 250]), "test", True)
    solved = response_from_json(response_to_json(response, "noisy", fitted, policy))
    noise = solved.noise
    for name in ("shot", "read", "code"):
        assert np.array_equal(getattr(noise, name), getattr(fitted, name))
    assert noise.source == "fitted"
    kept = solved.policy
    assert (list(kept.limits), list(kept.gates), kept.rule, kept.neutral) == (
        [250, 252, 254], [240, 245, 250], "test", True)


def test_exposures_follow_the_files_order(write_brackets):
    paths = write_brackets((1 / 16, 1 / 4, 1.0, 4.0))
    shuffled = [paths[2], paths[0], paths[3], paths[1]]
    values, source = exposures_for_files(shuffled)
    assert values == pytest.approx([1.0, 1 / 16, 4.0, 1 / 4])
    assert source == "filename"


def test_exposures_missing_names_the_file(write_brackets):
    paths = write_brackets((1 / 4, 1.0), names=["first.png", "second.png"])
    with pytest.raises(InputError, match="first.png: no exposure time"):
        exposures_for_files(paths)


def test_sorted_order_shortest_first_ties_in_input_order():
    assert sorted_order([4.0, 0.25, 1.0, 0.25]) == [1, 3, 2, 0]


def test_addon_imports_without_blender():
    code = ("import sys, plugins.blender, plugins.blender.baking, plugins.blender.exposures, "
            "plugins.blender.warmup, plugins.blender.build; "
            "assert 'bpy' not in sys.modules, 'bpy imported'")
    run = subprocess.run([sys.executable, "-c", code], cwd=REPOSITORY, capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stderr


def test_manifest_gets_platform_and_wheels_as_top_level_keys():
    tomllib = pytest.importorskip("tomllib", reason="TOML parser of Python 3.11+")
    wheels = [Path("hdrio-0.1.0-py3-none-any.whl"), Path("scipy-1.17.1-cp311.whl")]
    manifest = tomllib.loads(manifest_text("linux-x64", wheels))
    assert manifest["platforms"] == ["linux-x64"]
    assert manifest["wheels"] == [f"./wheels/{w.name}" for w in wheels]
    # What plugins/blender/ci/run_tests.sh tests, and nothing more (README).
    assert (manifest["blender_version_min"], manifest["blender_version_max"]) == (
        "4.5.0", "5.1.0")
    tested = (REPOSITORY / "plugins/blender/ci/run_tests.sh").read_text()
    assert 'versions="${HDRIO_BLENDER_VERSIONS:-4.5 5.0}"' in tested
    assert "wheels" not in manifest["permissions"]
    fields = manifest_fields(manifest_text("linux-x64", wheels))
    assert (fields["id"], fields["version"]) == (manifest["id"], manifest["version"])


def test_extension_ships_the_addon_modules_not_the_build_script():
    names = {path.name for path in extension_files()}
    assert {"__init__.py", "nodes.py", "operators.py", "baking.py"} <= names
    assert "build.py" not in names


def test_curve_points_land_on_blender_curve_table_samples():
    # 256 points for 8-bit codes: point k goes to k / 256, sample k of Blender's table.
    baked = bake_merge(smooth_response(), [1.0, 2.0])
    squeezed = baked.positions * table_squeeze(baked.positions) * CURVE_TABLE_SIZE
    np.testing.assert_allclose(squeezed, np.arange(256), rtol=0, atol=1e-9)
    # 16-bit codes rounded to integers are still even enough to align.
    sixteen = bake_merge(smooth_response(code_max=65535), [1.0, 2.0])
    assert table_squeeze(sixteen.positions) == pytest.approx(255 / 256)
    # Uneven points, or more points than samples, are left where they are.
    assert table_squeeze(np.array([0.0, 0.1, 1.0])) == 1.0
    assert table_squeeze(np.linspace(0.0, 1.0, 300)) == 1.0


def test_typed_exposures_replace_placeholders_and_the_state_says_so():
    sources = [PLACEHOLDER] * 3
    assert placeholder_brackets(sources) == [1, 2, 3]
    assert exposure_state(sources) == "Type exposure of bracket 1, 2, 3"
    sources = edited_sources(sources, [0.0625, 0.25, 1.0], [32.0, 0.25, 1.0])
    assert sources == [TYPED, PLACEHOLDER, PLACEHOLDER]
    sources = edited_sources(sources, [32.0, 0.25, 1.0], [32.0, 16.0, 8.0])
    assert placeholder_brackets(sources) == []
    assert exposure_state(sources) == "Exposures: typed"
    assert exposure_state(["exif", "exif"]) == "Exposures: exif"


def test_input_problems_name_the_bracket():
    assert input_problems([None, None], [False, False]) == ""  # a node just added
    assert input_problems([(4, 3), None], [True, False]) == "Bracket 2 is not linked"
    assert input_problems([(4, 3), (0, 0)], [True, True]) == "Bracket 2: image has no pixels"
    assert input_problems([(4, 3), (2, 3)], [True, True]) == "Bracket 2 is 2x3, bracket 1 4x3"
    # A linked render pass has no size to compare: fine.
    assert input_problems([(4, 3), None, (4, 3)], [True, True, True]) == ""


def test_warmup_runs_its_steps_once_and_reports_progress():
    calls = []
    warmup = KernelWarmup((("one", lambda: calls.append(1)), ("two", lambda: calls.append(2))))
    assert not warmup.running and warmup.status() == "hdrio: compiling kernels (0/2: one)"
    warmup.start()
    warmup.start()
    assert warmup.wait(10) and calls == [1, 2] and warmup.done == 2
    assert warmup.status() == "hdrio: kernels ready" and not warmup.running


def test_warmup_reports_a_failure_and_finishes():
    def broken():
        raise RuntimeError("no compiler")

    warmup = KernelWarmup((("broken", broken),))
    warmup.start()
    assert warmup.wait(10)
    assert warmup.status() == "hdrio: kernel warm-up failed (RuntimeError: no compiler)"


@pytest.mark.slow
def test_warmup_steps_compile_hdrio_kernels():
    warmup = KernelWarmup()
    warmup.start()
    assert warmup.wait(600) and not warmup.error, warmup.error
