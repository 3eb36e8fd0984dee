"""kill -9 at any point of a batch: no orphan pool worker, no temporary file left after
a rerun (Linux: reads /proc)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from hdrio.batch import merge_shoot

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
ROOT = Path(__file__).resolve().parents[1]
LADDER = (1 / 64, 1 / 16, 1 / 4)


def _children(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _pool_workers(pid: int) -> list[int]:
    """The pool workers of ``pid``: its children, or on Linux those of its fork server
    (hdrio.batch.pool.fork_server), multiprocessing's resource tracker left out."""
    found = []
    for child in _children(pid):
        try:
            command = Path(f"/proc/{child}/cmdline").read_bytes()
        except OSError:
            continue
        if b"multiprocessing.forkserver" in command:
            found += _children(child)
        elif b"resource_tracker" not in command:
            found.append(child)
    return found


def _alive(pid: int) -> bool:
    try:
        return "State:\tZ" not in Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False


def _wait_until(condition, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.1)
    return condition()


@pytest.fixture
def shoot(write_brackets, tmp_path) -> Path:
    folder = tmp_path / "shoot"
    for letter in "abcd":
        write_brackets(LADDER, folder=folder, size=(16, 24),
                       names=[f"pos_{letter}_1_{round(1 / t)}.png" for t in LADDER])
    return folder


_POOL_SCRIPT = textwrap.dedent("""
    import sys
    from hdrio.batch import merge_shoot
    from tests.test_batch_dask import SlowMerge

    if __name__ == "__main__":
        merge_shoot(sys.argv[1], sys.argv[2], work=SlowMerge(delay_s=60), workers=2)
""")


@pytest.mark.slow
def test_killing_the_parent_takes_its_pool_workers_down(shoot, tmp_path):
    script = tmp_path / "pool.py"
    script.write_text(_POOL_SCRIPT)
    parent = subprocess.Popen([sys.executable, str(script), str(shoot),
                               f"{tmp_path}/hdr/{{first_stem}}.exr"], cwd=ROOT,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert _wait_until(lambda: len(_pool_workers(parent.pid)) >= 2, 60)
        time.sleep(1.0)  # the workers are past their start-up
        workers = _pool_workers(parent.pid) + _children(parent.pid)  # and the server
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    assert _wait_until(lambda: not any(map(_alive, workers)), 10), "orphaned pool workers"


_WRITER_SCRIPT = textwrap.dedent("""
    import sys, time
    import numpy as np
    from hdrio.io.write import write_image

    def stall(rows):  # called per band of rows, after the temporary file is open
        print("writing", flush=True)
        time.sleep(600)
        return rows

    write_image(sys.argv[1], np.ones((128, 8, 3), np.float32), "float", band=stall)
""")


def test_a_writer_killed_mid_write_leaves_a_temporary_the_rerun_removes(shoot, tmp_path):
    out = tmp_path / "hdr"
    out.mkdir()
    path = out / "pos_a_1_64.exr"
    writer = subprocess.Popen([sys.executable, "-c", _WRITER_SCRIPT, str(path)], cwd=ROOT,
                              stdout=subprocess.PIPE, text=True)
    assert writer.stdout.readline().strip() == "writing"
    writer.send_signal(signal.SIGKILL)
    writer.wait()
    leftovers = list(out.glob(".*.partial.exr"))
    assert len(leftovers) == 1 and not path.exists()  # what kill -9 mid-write leaves

    tasks, results = merge_shoot(shoot, f"{out}/{{first_stem}}.exr", workers=1)
    assert len(results) == 4 and all(r.ok for r in results)
    assert not list(out.glob(".*.partial*")) and path.is_file()
