"""The report after a merge is the written file's check, counted as it was written."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.cms.checks import REC709_D65, StreamingCheck, check_pixels
from tests.conftest import run_cli as run


def _check_lines(text: str) -> list[str]:
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("check:"))
    return lines[start:]


@pytest.mark.parametrize("extra", [[], ["--colorspace", "ACEScg", "-d", "float"]])
def test_merge_report_equals_hdrio_check_of_the_file(brackets, tmp_path, capsys, extra):
    out = tmp_path / "out.exr"
    code, merged, err = run(capsys, "merge", *brackets, "-o", out, *extra)
    assert code == 0, err
    code, checked, err = run(capsys, "check", out)
    assert code == 0, err
    # Identical text: the same counts over the same stored values (half bands included).
    assert _check_lines(merged) == _check_lines(checked)


def test_streaming_check_agrees_with_the_exact_check():
    rng = np.random.default_rng(3)
    rgb = np.exp(rng.normal(0.0, 3.0, (300, 200, 3))).astype(np.float32)
    rgb[5, 5] = -1.0
    rgb[6, 6, 1] = np.nan
    exact = check_pixels(rgb, REC709_D65)
    check = StreamingCheck(REC709_D65)
    for top in range(0, 300, 64):  # bands, as a file is read or written
        check.add(rgb[top:top + 64])
    streamed = check.report()
    assert (streamed.negative, streamed.non_finite) == (exact.negative, exact.non_finite)
    assert streamed.out_of_gamut == exact.out_of_gamut
    # Exact extremes; percentiles of the positive luminances from bins 2**-11 (0.05 %)
    # wide, interpolated as numpy does: within 0.1 % of numpy's.
    assert streamed.dynamic_range_stops == pytest.approx(exact.dynamic_range_stops, abs=1e-6)
    assert streamed.robust_range_stops == pytest.approx(exact.robust_range_stops, abs=3e-3)
    Y = rgb.reshape(-1, 3).astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    Y = Y[np.isfinite(Y) & (Y > 0)]
    for name, q in (("p1", 1), ("median", 50), ("p99", 99)):
        assert streamed.luminance_percentiles[name] == pytest.approx(np.percentile(Y, q),
                                                                     rel=1e-3)


@pytest.mark.parametrize("gamut", [None, "ITU-R BT.709"])
def test_streaming_check_counted_on_threads_in_any_order_is_the_same(gamut):
    """``hdrio check`` counts an image on every core, in pieces that finish in any order:
    the counts merge to exactly what one pass in order gives."""
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng(5)
    rgb = np.exp(rng.normal(0.0, 2.5, (257, 190, 3))).astype(np.float16)
    rgb[7, 3] = [-0.5, 1.0, 1.0]
    rgb[9, 9, 2] = np.inf
    rgb[:20, :20] = [0.0, 1.0, 0.0]  # outside Rec.709 when the file's primaries are ACEScg
    acescg = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
    in_order = StreamingCheck(acescg, gamut=gamut)
    in_order.add(rgb)
    threaded = StreamingCheck(acescg, gamut=gamut)
    pieces = [(top, top + 13) for top in range(0, 257, 13)][::-1]
    with ThreadPoolExecutor(4) as pool:
        list(pool.map(lambda piece: threaded.add_planes(
            *(rgb[piece[0]:piece[1], :, c] for c in range(3))), pieces))
    a, b = in_order.report(), threaded.report()
    assert (a.pixels, a.negative, a.non_finite) == (b.pixels, b.negative, b.non_finite)
    assert a.out_of_gamut == b.out_of_gamut and (gamut is None or a.out_of_gamut > 0.008)
    assert a.luminance_percentiles == b.luminance_percentiles
    assert (a.dynamic_range_stops, a.robust_range_stops) == \
        (b.dynamic_range_stops, b.robust_range_stops)
    with np.errstate(invalid="ignore"):  # the inf pixel
        exact = check_pixels(rgb.astype(np.float32), acescg, gamut=gamut)
    assert (a.negative, a.non_finite, a.out_of_gamut) == \
        (exact.negative, exact.non_finite, exact.out_of_gamut)


def test_check_of_a_truncated_exr_names_the_file(tmp_path, capsys, brackets):
    out = tmp_path / "out.exr"
    assert run(capsys, "merge", *brackets, "-o", out, "-q")[0] == 0
    broken = tmp_path / "broken.exr"
    broken.write_bytes(out.read_bytes()[: out.stat().st_size // 2])
    code, _, err = run(capsys, "check", broken)
    assert code == 2
    assert err.strip().splitlines()[-1].endswith(
        "broken.exr: cannot decode pixels: the file is damaged or truncated")
