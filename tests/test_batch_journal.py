"""What is done: set fingerprints, the journal, --force, shards, --list-sets, and the
clean-up of temporary files that killed writers left behind."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hdrio.batch import (
    BracketSet,
    Frame,
    is_done,
    parse_shard,
    plan_sets,
    record_done,
    set_fingerprint,
    stale_partials,
)
from hdrio.batch.partial import clean_partials
from hdrio.cli import main
from hdrio.io.write import temporary_name, temporary_writer, this_writer

EXPOSURES = ((1 / 64, 1 / 16, 1 / 4), (1 / 32, 1 / 8, 1 / 2))


@pytest.fixture
def two_sets(write_brackets, tmp_path) -> Path:
    """Two 3-frame sets of small PNGs, exposures in the names: a_1_64.png ..., b_1_32.png ..."""
    folder = tmp_path / "shoot"
    for stem, times in zip("ab", EXPOSURES):
        write_brackets(times, folder=folder, size=(12, 16),
                       names=[f"{stem}_1_{round(1 / t)}.png" for t in times])
    return folder


def _run(folder: Path, out: Path, *extra: str, merge: tuple[str, ...] = ("--merge",)):
    return main(["--threads", "1", str(folder), *extra, "--group", *merge,
                 "-o", f"{out}/{{first_stem}}.exr"])


def _stamps(out: Path) -> dict[str, int]:
    return {p.name: p.stat().st_mtime_ns for p in out.glob("*.exr")}


def test_unchanged_rerun_does_nothing_a_setting_redoes_force_redoes_all(two_sets, tmp_path,
                                                                      capsys):
    out = tmp_path / "hdr"
    assert _run(two_sets, out) == 0
    assert "2 to merge, 0 done" in capsys.readouterr().out
    first = _stamps(out)
    assert len(first) == 2

    assert _run(two_sets, out) == 0  # unchanged: nothing redone
    assert "0 to merge, 2 done" in capsys.readouterr().out
    assert _stamps(out) == first

    # Any merge setting changes the fingerprint: every set is redone.
    assert _run(two_sets, out, merge=("--merge", "linear")) == 0
    assert "2 to merge, 0 done" in capsys.readouterr().out
    second = _stamps(out)
    assert all(second[name] != first[name] for name in first)
    assert _run(two_sets, out, merge=("--merge", "linear")) == 0
    assert "0 to merge, 2 done" in capsys.readouterr().out

    assert _run(two_sets, out, "--force", merge=("--merge", "linear")) == 0  # --force
    assert "2 to merge, 0 done" in capsys.readouterr().out
    assert all(_stamps(out)[name] != second[name] for name in second)


def test_a_changed_input_or_a_lost_output_redoes_only_its_set(two_sets, tmp_path, capsys):
    out = tmp_path / "hdr"
    assert _run(two_sets, out) == 0
    capsys.readouterr()
    before = _stamps(out)
    frame = two_sets / "a_1_16.png"
    os.utime(frame, ns=(frame.stat().st_atime_ns, frame.stat().st_mtime_ns + 10**9))
    assert _run(two_sets, out) == 0
    assert "1 to merge, 1 done" in capsys.readouterr().out
    after = _stamps(out)
    assert after["b_1_32.exr"] == before["b_1_32.exr"] and after["a_1_64.exr"] != before[
        "a_1_64.exr"]
    (out / "b_1_32.exr").unlink()  # an output deleted (or replaced) is not done
    assert _run(two_sets, out) == 0
    assert "1 to merge, 1 done" in capsys.readouterr().out
    assert (out / "b_1_32.exr").is_file()


def test_fingerprint_covers_inputs_recipe_and_named_files(tmp_path):
    a, sidecar = tmp_path / "a.png", tmp_path / "list.csv"
    a.write_bytes(b"x")
    sidecar.write_text("file,exposure_time_s\n")
    base = set_fingerprint([a], ["--merge"], [sidecar])
    assert base == set_fingerprint([a], ["--merge"], [sidecar])
    assert base != set_fingerprint([a], ["--merge", "linear"], [sidecar])
    sidecar.write_text("file,exposure_time_s\na.png,1\n")
    assert base != set_fingerprint([a], ["--merge"], [sidecar])


def test_journal_record_needs_the_same_fingerprint_and_untouched_outputs(tmp_path):
    output = tmp_path / "x.exr"
    output.write_bytes(b"exr")
    assert not is_done([output], "f1")
    record_done([output], "f1")
    assert is_done([output], "f1") and not is_done([output], "f2")
    output.write_bytes(b"another exr")
    assert not is_done([output], "f1")
    assert not is_done([], "f1")  # a set without outputs is never done


# ------------------------------------------------------------------------------- shards


def _sets(count: int) -> list[BracketSet]:
    return [BracketSet((Frame(Path(f"s{k}_a.png"), 1.0, None, None),
                        Frame(Path(f"s{k}_b.png"), 4.0, None, None))) for k in range(count)]


@pytest.mark.parametrize("count, parts", [(12, 5), (3, 4), (7, 7), (100, 8)])
def test_shards_cover_every_set_exactly_once(count, parts, tmp_path):
    def outputs(fields):
        return [tmp_path / f"{fields['index']}.exr"]

    whole = [t.index for t in plan_sets(_sets(count), outputs, [])]
    shards = [[t.index for t in plan_sets(_sets(count), outputs, [], shard=(k, parts))]
              for k in range(1, parts + 1)]
    assert sorted(i for shard in shards for i in shard) == whole
    assert max(map(len, shards)) - min(map(len, shards)) <= 1  # equal parts


def test_parse_shard_refuses_nonsense():
    assert parse_shard("3/10") == (3, 10)
    for text in ("0/3", "4/3", "3", "a/b", "1/0"):
        with pytest.raises(ValueError, match="K/N|1 .. N"):
            parse_shard(text)


def test_list_sets_json_with_shards_matches_the_whole(two_sets, tmp_path, capsys):
    out = tmp_path / "hdr"
    pattern = f"{out}/{{first_stem}}.exr"
    assert main([str(two_sets), "--list-sets", "--group", "--merge", "-o", pattern]) == 0
    whole = json.loads(capsys.readouterr().out)
    assert [s["index"] for s in whole] == [1, 2] and {s["status"] for s in whole} == {"run"}
    assert whole[0]["exposure_times_s"] == pytest.approx(EXPOSURES[0])
    assert whole[0]["outputs"] == [f"{out}/a_1_64.exr"] and len(whole[0]["fingerprint"]) == 64
    parts = []
    for k in (1, 2):
        assert main([str(two_sets), "--shard", f"{k}/2", "--list-sets", "--group",
                     "--merge", "-o", pattern]) == 0
        parts += json.loads(capsys.readouterr().out)
    assert parts == whole
    assert not out.exists()  # listing writes nothing


def test_batch_options_without_group_are_refused(two_sets, capsys):
    code = main([str(two_sets / "a_1_64.png"), str(two_sets / "a_1_16.png"), "--force",
                 "--merge", "-o", "x.exr"])
    assert code == 2 and "--force: only with --group" in capsys.readouterr().err


# ----------------------------------------------------------------- stale temporary files


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_only_temporaries_of_dead_writers_on_this_host_are_cleaned(tmp_path):
    host, pid = this_writer()
    ours = temporary_name(tmp_path / "a.exr")
    assert temporary_writer(ours) == (host, pid)
    dead = tmp_path / f".b.{host}-{_dead_pid()}-0123abcd.partial.exr"
    live = tmp_path / f".c.{host}-{pid}-0123abcd.partial.exr"  # this process: being written
    remote = tmp_path / ".d.render-node-7-123-0123abcd.partial.exr"  # pid means nothing here
    other = tmp_path / ".e.0123abcd.partial.exr"  # not hdrio's pattern (an old name)
    for path in (dead, live, remote, other):
        path.write_bytes(b"half-written")
    assert temporary_writer(remote) == ("render-node-7", 123)
    assert stale_partials([tmp_path]) == [dead]
    assert clean_partials([tmp_path]) == [dead]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        p.name for p in (live, remote, other))


def test_a_batch_removes_stale_temporaries_in_its_output_folders(two_sets, tmp_path,
                                                                capsys):
    out = tmp_path / "hdr"
    out.mkdir()
    host, _pid = this_writer()
    stale = out / f".a_1_64.{host}-{_dead_pid()}-0123abcd.partial.exr"
    stale.write_bytes(b"half-written")
    assert _run(two_sets, out) == 0
    assert not stale.exists()
    assert not list(out.glob(".*.partial*"))


def test_hdrio_batch_imports_neither_the_cli_nor_dask():
    code = ("import sys, hdrio.batch; print(sorted(m for m in sys.modules "
            "if m.startswith(('hdrio.cli', 'distributed', 'dask'))))")
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                               check=True)
    assert completed.stdout.strip() == "[]"


def test_sets_of_another_count_than_group_size_are_skipped_and_said_why(tmp_path):
    three = BracketSet(tuple(Frame(Path(f"c{k}.png"), 4.0**k, None, k) for k in range(3)))
    tasks = plan_sets([*_sets(2), three], lambda f: [tmp_path / f"{f['index']}.exr"], [],
                      size=2)
    assert [t.status for t in tasks] == ["run", "run", "skip: 3 frames, --group-size is 2"]
