"""benchmarks/tonemap.py end to end on a tiny image: the table, the JSON, the ratios.
Checks structure and arithmetic only, never a time."""

from __future__ import annotations

import json

import pytest

from benchmarks.tonemap import main

OPENCV = "OpenCV TonemapReinhard (other operator, global)"


def test_benchmark_writes_json_with_consistent_ratios(tmp_path, capsys):
    path = tmp_path / "tonemap.json"
    assert main(["--width", "64", "--height", "48", "--repeats", "2", "--json", str(path),
                 "--no-compile"]) == 0
    results = json.loads(path.read_text())
    rows = results["rows"]
    assert {(r["width"], r["height"]) for r in rows} == {(64, 48), (16, 12)}
    methods = {r["method"] for r in rows}
    assert {"floor: copy", "hdrio global", "hdrio local", "reference global (numpy)",
            "reference local (numpy/scipy)"} <= methods
    for size in ((64, 48), (16, 12)):
        mine = {r["method"]: r for r in rows if (r["width"], r["height"]) == size}
        floor = mine["floor: copy"]["median_s"]
        for r in mine.values():
            assert r["median_s"] > 0 and r["min_s"] <= r["median_s"]
            # rel 1e-9: the ratio is computed from the same stored floats.
            assert r["x_floor"] == pytest.approx(r["median_s"] / floor, rel=1e-9)
        for kind, reference in (("global", "reference global (numpy)"),
                                ("local", "reference local (numpy/scipy)")):
            ratio = mine[reference]["median_s"] / mine[f"hdrio {kind}"]["median_s"]
            assert mine[f"hdrio {kind}"]["speedup_vs_reference"] == pytest.approx(ratio,
                                                                                  rel=1e-9)
        if OPENCV in mine:
            assert mine[OPENCV]["x_opencv"] == pytest.approx(1.0)
    assert len(results["load_average_before"]) == 3 and results["compile"] == {}
    printed = capsys.readouterr().out
    assert "| 64x48 | hdrio local |" in printed and "load average" in printed


@pytest.mark.parametrize("argv", [["--repeats", "0"], ["--width", "-3"],
                                  ["--json", "/nonexistent-folder/x.json"]])
def test_benchmark_refuses_bad_arguments(argv, capsys):
    assert main(argv) == 2
    assert capsys.readouterr().err.startswith("error: ")
