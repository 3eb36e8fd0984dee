"""NaN and Inf in float inputs: replaced by a stated rule, said in one line, and the
tone-mapped picture looks like the clean one."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from hdrio.errors import InputError
from hdrio.io.images import replace_non_finite
from hdrio.io.write import write_exr
from hdrio.tonemap import TONEMAP_METHODS
from hdrio.tools.synthetic import demo_scene
from tests.conftest import run_cli


def _damaged(clean: np.ndarray) -> np.ndarray:
    """12 NaN rows of 96, a NaN block, 40 scattered NaN, 25 +Inf and 5 -Inf pixels."""
    rng = np.random.default_rng(3)
    damaged = clean.copy()
    damaged[30:42] = np.nan
    damaged[60:70, 20:50] = np.nan
    flat = damaged.reshape(-1, 3)
    flat[rng.choice(flat.shape[0], 40, replace=False)] = np.nan
    flat[rng.choice(flat.shape[0], 25, replace=False)] = np.inf
    flat[rng.choice(flat.shape[0], 5, replace=False), 1] = -np.inf
    return damaged


def _preview_mean(path, tmp_path, capsys, name: str, operator: str = "reinhard-global"
                  ) -> tuple[float, str]:
    png = tmp_path / f"{name}.png"
    code, _out, err = run_cli(capsys, path, "--tonemap", operator, "-o", png)
    assert code == 0, err
    pixels = oiio.ImageBuf(str(png)).get_pixels(oiio.FLOAT)
    return float(np.mean(pixels)), err


def test_tonemapped_mean_within_5_percent_of_the_clean_image(tmp_path, capsys):
    clean = demo_scene(96, 144)
    write_exr(tmp_path / "clean.exr", clean, pixel_type="float")
    write_exr(tmp_path / "damaged.exr", _damaged(clean), pixel_type="float")
    clean_mean, clean_err = _preview_mean(tmp_path / "clean.exr", tmp_path, capsys, "c")
    damaged_mean, err = _preview_mean(tmp_path / "damaged.exr", tmp_path, capsys, "d")
    assert clean_err == ""  # nothing to say about a clean file
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "damaged.exr" in lines[0] and "replaced" in lines[0], err
    # Pixels with any non-finite channel: 12 rows x 144 + 10 x 30 + 40 + 25 + 5 at most
    # (random picks may overlap the rows and each other).
    count = int(lines[0].split("replaced non-finite values in ")[1].split()[0])
    assert 12 * 144 + 300 < count <= 12 * 144 + 300 + 70
    # The bar: the preview's mean within 5 % of the clean image's (before the
    # fix a NaN made the scene key NaN and the picture nearly black).
    assert damaged_mean == pytest.approx(clean_mean, rel=0.05)


def test_the_rule_nan_nearest_inf_channel_range():
    pixels = np.array([[[1.0], [np.nan], [3.0], [np.inf], [-np.inf]]], np.float32)
    fixed, note = replace_non_finite(pixels, "x.exr")
    # NaN at column 1: columns 0 and 2 are equally near; either neighbour is the rule.
    assert fixed[0, 1, 0] in (1.0, 3.0)
    assert fixed[0, 3, 0] == 3.0 and fixed[0, 4, 0] == 1.0  # the finite max and min
    assert "3 of 5 pixels" in note and "1 NaN, 1 +Inf, 1 -Inf" in note


def test_clean_pixels_are_returned_untouched():
    pixels = np.ones((2, 2, 3), np.float32)
    fixed, note = replace_non_finite(pixels)
    assert note is None and fixed is pixels


def test_a_channel_without_any_finite_value_is_refused():
    pixels = np.full((2, 2, 1), np.nan, np.float32)
    with pytest.raises(InputError, match="x.exr: channel 0 has no finite value"):
        replace_non_finite(pixels, "x.exr")


@pytest.mark.parametrize("operator", list(TONEMAP_METHODS))
def test_every_operator_treats_damaged_and_negative_pixels_alike(operator, tmp_path, capsys):
    """NaN, +-Inf and negative pixels (a merge's noise below black, an edit's overshoot)
    leave every operator's picture like the clean one (before, the tutorial's global
    operator took the log of a negative luminance and made the whole picture black)."""
    clean = demo_scene(96, 144)
    damaged = _damaged(clean)
    damaged[80:84, 100:120] = -0.5  # 80 negative pixels
    damaged[5, 5, 2] = -3.0  # one negative channel
    write_exr(tmp_path / "clean.exr", clean, pixel_type="float")
    write_exr(tmp_path / "damaged.exr", damaged, pixel_type="float")
    clean_mean, _ = _preview_mean(tmp_path / "clean.exr", tmp_path, capsys, "c", operator)
    damaged_mean, _ = _preview_mean(tmp_path / "damaged.exr", tmp_path, capsys, "d",
                                    operator)
    # 5 %: the repaired NaN/Inf pixels take their neighbours' or the channel's extreme
    # values and the 81 negatives show black (the reinhard-global case above: 1-2 %).
    assert damaged_mean == pytest.approx(clean_mean, rel=0.05)


def test_tutorial_global_key_counts_negative_luminance_as_zero():
    """The key (eq. 1) of the tutorial's operator is the paper variants' key: negative
    luminance counts as 0; the negative pixel itself comes out NaN or negative, which
    the preview shows black."""
    from hdrio.tonemap import tonemap_Reinhard2002_global_tutorial

    clean = demo_scene(24, 32).astype(np.float64)
    damaged = clean.copy()
    damaged[0, 0] = -1.0
    out = tonemap_Reinhard2002_global_tutorial(damaged)
    zeroed = clean.copy()
    zeroed[0, 0] = 0.0
    reference = tonemap_Reinhard2002_global_tutorial(zeroed)
    assert (np.nan_to_num(out[0, 0], nan=0.0) <= 0).all()
    # Equal elsewhere to float64 rounding: the same key, the same per-pixel formula.
    np.testing.assert_allclose(out.reshape(-1, 3)[1:], reference.reshape(-1, 3)[1:],
                               rtol=1e-12)
