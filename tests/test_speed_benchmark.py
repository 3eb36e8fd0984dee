"""The speed benchmark runs end to end on a tiny size (tests never assert a timing)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.speed.__main__ import main

# Slow (runs the speed benchmark's sections): deselected by default, run by
# `pytest -m slow` (CI runs both).
pytestmark = pytest.mark.slow


def test_speed_benchmark_writes_rows_and_ratios(tmp_path, capsys):
    pytest.importorskip("cv2", reason="OpenCV (the bench extra) is the peer being timed")
    assert main(["--width", "96", "--height", "64", "--brackets", "5", "--repeats", "1",
                 "--only", "merge,response,endtoend", "--out", str(tmp_path)]) == 0
    results = json.loads((tmp_path / "speed.json").read_text())
    methods = {row["method"] for row in results["rows"]}
    assert {"hdrio merge (log)", "hdrio merge (linear)", "OpenCV MergeDebevec",
            "floor (copy of the codes, all cores)", "I/O floor (decode JPEGs + write EXR)",
            "hdrio merge process, 5 JPEGs"} <= methods
    merges = [row for row in results["rows"]
              if row["row"] == "merge" and row["method"].startswith("hdrio")]
    # Same brackets, same true response: hdrio's merge is accurate where it is exposed.
    assert all(row["median_error"] < 0.03 for row in merges)
    assert all(value is None or value > 0 for value in results["ratios"].values())
    assert "| merge |" in capsys.readouterr().out


def test_unknown_section_is_refused(tmp_path):
    assert main(["--only", "nope", "--out", str(tmp_path)]) == 2


def test_skips_section_times_every_skip_on_and_off(tmp_path):
    from hdrio.skips import SKIPS

    assert main(["--width", "96", "--height", "64", "--repeats", "1", "--only", "skips",
                 "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "speed.json").read_text())["rows"]
    timed = {(row["skip"], row["state"]) for row in rows if row["row"] == "skips"}
    assert timed == {(name, state) for name in SKIPS for state in ("on", "off")}


def test_process_section_times_the_commands_users_type(tmp_path):
    assert main(["--width", "96", "--height", "64", "--repeats", "1", "--only", "process",
                 "--out", str(tmp_path)]) == 0
    results = json.loads((tmp_path / "speed.json").read_text())
    rows = [row for row in results["rows"] if row["row"] == "process"]
    assert {row.get("merge_of") for row in rows} >= {5, 7, 9}
    assert {row.get("floor_of") for row in rows} >= {5, 7, 9}
    assert any(row.get("check") for row in rows)
    assert any(row.get("preview_of") == 7 for row in rows)  # as the README's commands
    assert results["ratios"]["process: hdrio merge 7 JPEGs with a preview / without"] > 0
    assert {row.get("demo") for row in rows} >= {"cold", "warm"}
    # Peak memory from the OS for each process: a real Python process holds > 10 MB.
    assert all(row["process_peak_mb"] > 10 for row in rows)
    assert results["ratios"]["process: hdrio merge 7 JPEGs / I/O floor process"] > 0


def test_a_merges_log_is_split_into_its_stages():
    from benchmarks.cores import stages

    log = ("[  0.00 s] reading 7 brackets\n[  0.34 s] camera response: Debevec1997\n"
           "[  0.91 s] aligning 7 brackets (auto)\n[  1.01 s] deghosting\n"
           "[  1.32 s] merging 7 brackets\n[  1.80 s] writing out.exr\n"
           "wrote:     out.exr (half, zip) in 0.60 s\n")
    found = stages(log, 3.0)
    assert found["reading"] == pytest.approx(0.34)
    assert found["camera"] == pytest.approx(0.57)
    assert found["writing"] == pytest.approx(0.60)
    assert found["start-up and exit"] == pytest.approx(3.0 - 2.40)


def test_a_log_with_the_cpu_column_gives_each_stages_cpu_seconds(monkeypatch):
    import io

    from benchmarks.cores import cpu_stages, stages
    from hdrio.cli.progress import Progress

    monkeypatch.setenv("HDRIO_PROGRESS_CPU", "1")
    stream = io.StringIO()
    progress = Progress(stream=stream)
    progress.step("reading 7 brackets")
    progress.step("camera response: Debevec1997")
    first, second = stream.getvalue().splitlines()
    assert first.startswith("[") and ", CPU " in first and first.endswith("reading 7 brackets")
    # the process's CPU seconds since it started, at each line: never less at a later one
    assert float(second.split("CPU")[1].split()[0]) >= float(first.split("CPU")[1].split()[0])
    log = ("[  0.00 s, CPU   4.80 s] reading 7 brackets\n"
           "[  0.56 s, CPU   7.30 s] camera response: Debevec1997\n"
           "[  1.00 s, CPU   7.90 s] writing out.exr\n"
           "wrote:     out.exr (half, zip) in 0.60 s\n")
    assert stages(log, 2.0)["reading"] == pytest.approx(0.56)
    found = cpu_stages(log, 12.0)
    assert found == pytest.approx({"before the first line": 4.8, "reading": 2.5,
                                   "camera": 0.6, "writing": 4.1})
    assert cpu_stages("[  0.00 s] reading 7 brackets\n", 1.0) == {}


def test_the_many_core_run_measures_the_merge_its_floor_and_a_shoot(tmp_path):
    # What docs/speed.md's "Many cores" table comes from, on a tiny ladder: every row a
    # process with its CPU seconds and peak from the OS, the ratios from rows of one run.
    from benchmarks.cores import main as cores

    # --baseline: another tree's hdrio, alternated (here the checkout's own tree, whose
    # kernels are cached; a tree without hdrio/ is refused, not silently replaced)
    root = Path(__file__).resolve().parents[1]
    assert cores(["--size", "64x96", "--cores", "1,all", "--scaling", "1", "--repeats", "1",
                  "--sets", "2", "--shoot-size", "48x64", "--workers", "1,2", "--dask", "",
                  "--baseline", str(root), "--out", str(tmp_path)]) == 0
    results = json.loads((tmp_path / "cores.json").read_text())
    sections = {row["section"] for row in results["rows"]}
    assert sections == {"merge 7 x 24 MP", "peak", "scaling", "first run"}
    assert all(row["peak_mb"] > 10 and row["cpu_seconds"] > 0 for row in results["rows"])
    assert results["ratios"]["1 cores: merge / floor (wall)"] > 0
    assert results["ratios"]["1 cores: baseline / floor (wall)"] > 0
    with pytest.raises(SystemExit, match="python -m hdrio runs"):
        cores(["--size", "64x96", "--cores", "1", "--scaling", "", "--repeats", "1",
               "--sets", "0", "--baseline", str(tmp_path), "--out", str(tmp_path / "no")])
    assert "merging" in next(row for row in results["rows"]
                             if row["section"] == "scaling")["stages"]
    shoot = json.loads((tmp_path / "farm.json").read_text())
    assert "pool 2 / 1 workers" in shoot["throughput_ratios"]
    # and the baseline's shoot, row by row after this one's (not the single set)
    assert shoot["throughput_ratios"][
        "--group, local pool of 2 (--threads 2): this / the baseline (sets/min)"] > 0
    assert sum(row["run"].endswith(" (baseline)") for row in shoot["rows"]) == 2


def test_the_motion_benchmark_measures_the_solved_path_against_the_truth(tmp_path, capsys):
    """``benchmarks.motion`` (tiny: 384 x 512, one repeat) prints and writes every row,
    including the moving stack merged with its response solved (what a user runs; the
    other rows give the true response): its error over the still stack's, finite and
    positive, and the phases' ratio."""
    from benchmarks.motion import main as motion

    out = tmp_path / "motion.json"
    assert motion(["--size", "384x512", "--brackets", "5", "--repeats", "1", "--json",
                   str(out)]) == 0
    rows, printed = json.loads(out.read_text())["rows"], capsys.readouterr().out
    for name in ("solved: median error / the still stack's",
                 "solved: p99 error / the still stack's",
                 "solved: alignment, re-merge and deghosting / merge, wall"):
        assert 0 < rows[name] < float("inf") and name in printed, (name, rows[name])
