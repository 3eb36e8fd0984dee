"""The Blender extension's pure-Python parts (no ``bpy``): run in the main suite too."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hdrio.errors import InputError
from hdrio.merge.weighting import weights_table
from hdrio.response.curve import CameraResponse
from plugins.blender.baking import (
    CURVE_TABLE_SIZE,
    BakedResponse,
    bake_response,
    linear_response,
    table_squeeze,
)
from plugins.blender.build import extension_files, manifest_fields, manifest_text
from plugins.blender.exposures import exposures_for_files, sorted_order

REPOSITORY = Path(__file__).resolve().parents[3]


def smooth_response(code_max: int = 255, channels: int = 3) -> CameraResponse:
    """A gamma-like response with a tint per channel and unsupported ends."""
    z = np.maximum(np.arange(code_max + 1, dtype=np.float64), 0.5) / code_max
    g = np.stack([(2.0 + 0.2 * c) * np.log(z) for c in range(channels)], axis=1)
    supported = np.zeros_like(g, dtype=bool)
    supported[code_max // 20: code_max - code_max // 50] = True
    return CameraResponse(g, code_max, supported)


def test_baked_inverse_times_peak_is_the_response_at_every_8bit_code():
    response = smooth_response()
    baked = bake_response(response)
    assert np.array_equal(baked.positions, np.arange(256) / 255)
    assert baked.inverse.max(axis=0) == pytest.approx(np.ones(3))
    # float64 exp(g - max) * exp(max) against exp(g): rounding only (1e-12 relative).
    np.testing.assert_allclose(baked.inverse * baked.peak, np.exp(response.log_inverse),
                               rtol=1e-12)


def test_baked_weights_are_hdrio_merge_weights_up_to_a_factor():
    response = smooth_response()
    baked = bake_response(response, "Debevec1997")
    expected = weights_table("Debevec1997", 255)[:, None] * response.supported
    assert np.all(baked.weights[~response.supported] == 0)
    assert baked.weights.max(axis=0) == pytest.approx(np.ones(3))
    # Same shape up to one factor per channel: the weighted mean does not see it.
    factor = expected.max(axis=0)
    np.testing.assert_allclose(baked.weights * factor, expected, rtol=1e-12)


def test_16bit_response_is_sampled_at_256_codes_and_grey_fills_rgb():
    response = smooth_response(code_max=65535, channels=1)
    baked = bake_response(response)
    codes = np.rint(baked.positions * 65535).astype(int)
    assert codes.size == 256 and codes[0] == 0 and codes[-1] == 65535
    assert baked.inverse.shape == (256, 3)
    np.testing.assert_allclose(baked.inverse[:, 0] * baked.peak[0],
                               np.exp(response.log_inverse[codes, 0]), rtol=1e-12)
    assert np.array_equal(baked.inverse[:, 0], baked.inverse[:, 2])
    assert baked.saturation_level == pytest.approx(65534.5 / 65535)


def test_json_round_trip_keeps_every_table():
    baked = bake_response(smooth_response(), label="from test")
    again = BakedResponse.from_json(baked.to_json())
    for name in ("positions", "inverse", "peak", "weights"):
        assert np.array_equal(getattr(again, name), getattr(baked, name)), name
    assert (again.code_max, again.label) == (255, "from test")


def test_bake_refuses_degenerate_input():
    with pytest.raises(ValueError, match="at least 2 points"):
        bake_response(smooth_response(), points=1)
    response = smooth_response()
    unsupported = response.supported.copy()
    unsupported[:, 1] = False
    with pytest.raises(ValueError, match="no supported code value"):
        bake_response(CameraResponse(response.log_inverse, 255, unsupported))


def test_linear_response_is_proportional_to_code():
    baked = bake_response(linear_response())
    # exp(log(k / 255)) in float64: rounding only.
    np.testing.assert_allclose(baked.inverse[1:, 1], np.arange(1, 256) / 255, rtol=1e-12)
    assert baked.saturation_level == pytest.approx(254.5 / 255)


def test_exposures_follow_the_files_order(write_brackets):
    paths = write_brackets((1 / 16, 1 / 4, 1.0, 4.0))
    shuffled = [paths[2], paths[0], paths[3], paths[1]]
    assert exposures_for_files(shuffled) == pytest.approx([1.0, 1 / 16, 4.0, 1 / 4])


def test_exposures_missing_names_the_file(write_brackets):
    paths = write_brackets((1 / 4, 1.0), names=["first.png", "second.png"])
    with pytest.raises(InputError, match="first.png: no exposure time"):
        exposures_for_files(paths)


def test_sorted_order_shortest_first_ties_in_input_order():
    assert sorted_order([4.0, 0.25, 1.0, 0.25]) == [1, 3, 2, 0]


def test_addon_imports_without_blender():
    code = ("import sys, plugins.blender, plugins.blender.baking, plugins.blender.exposures, "
            "plugins.blender.build; assert 'bpy' not in sys.modules, 'bpy imported'")
    run = subprocess.run([sys.executable, "-c", code], cwd=REPOSITORY, capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stderr


def test_manifest_gets_platform_and_wheels_as_top_level_keys():
    tomllib = pytest.importorskip("tomllib", reason="TOML parser of Python 3.11+")
    wheels = [Path("hdrio-0.1.0-py3-none-any.whl"), Path("scipy-1.17.1-cp311.whl")]
    manifest = tomllib.loads(manifest_text("linux-x64", wheels))
    assert manifest["platforms"] == ["linux-x64"]
    assert manifest["wheels"] == [f"./wheels/{w.name}" for w in wheels]
    assert manifest["blender_version_min"] == "4.2.0"
    assert "wheels" not in manifest["permissions"]
    fields = manifest_fields(manifest_text("linux-x64", wheels))
    assert (fields["id"], fields["version"]) == (manifest["id"], manifest["version"])


def test_extension_ships_the_addon_modules_not_the_build_script():
    names = {path.name for path in extension_files()}
    assert {"__init__.py", "nodes.py", "operators.py", "baking.py"} <= names
    assert "build.py" not in names


def test_curve_points_land_on_blender_curve_table_samples():
    # 256 points for 8-bit codes: point k goes to k / 256, sample k of Blender's table.
    baked = bake_response(smooth_response())
    squeezed = baked.positions * table_squeeze(baked.positions) * CURVE_TABLE_SIZE
    np.testing.assert_allclose(squeezed, np.arange(256), rtol=0, atol=1e-9)
    # 16-bit codes rounded to integers are still even enough to align.
    sixteen = bake_response(smooth_response(code_max=65535))
    assert table_squeeze(sixteen.positions) == pytest.approx(255 / 256)
    # Uneven points, or more points than samples, are left where they are.
    assert table_squeeze(np.array([0.0, 0.1, 1.0])) == 1.0
    assert table_squeeze(np.linspace(0.0, 1.0, 300)) == 1.0
