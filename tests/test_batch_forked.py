"""Workers forked from hdrio's fork server (Linux): what they have loaded, the share of
threads they are given, and the server gone once the batch is done; the pool's and
``--dask local:N``'s."""

from __future__ import annotations

import multiprocessing.forkserver
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from hdrio.batch import SetTask, run_local
from hdrio.batch.pool import worker_threads
from hdrio.cli import main
from hdrio.io.images import read_image

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="workers are forked on Linux only")
LADDER = (1 / 64, 1 / 16, 1 / 4)


def _server_pid():
    return multiprocessing.forkserver._forkserver._forkserver_pid  # noqa: SLF001


@dataclass(frozen=True)
class Report:
    """A set's work that says what its worker had loaded before it, and its threads."""

    parent: int

    def __call__(self, task: SetTask) -> tuple[bool, str]:
        import numba

        return True, " ".join(map(str, (
            "hdrio.batch.worker_start" in sys.modules, "hdrio.job.run" in sys.modules,
            "numba.cpython.cmathimpl" in sys.modules,  # numba's CPU target loaded
            os.environ.get("HDRIO_THREADS"), numba.config.NUMBA_NUM_THREADS,
            os.getppid() != self.parent)))


def test_pool_workers_are_forked_with_what_a_set_needs_and_their_share(tmp_path):
    assert _server_pid() is None
    tasks = [SetTask(index=k, files=(), times_s=(), fields={}, outputs=(), fingerprint="",
                     status="run") for k in range(1, 5)]
    results = run_local(tasks, Report(os.getpid()), workers=2)
    share = worker_threads(2)  # numba's pool is sized to it when the server loads numba
    assert {r.printed for r in results} == {f"True True True {share} {share} True"}
    assert _server_pid() is None  # stopped with the pool
    preload = multiprocessing.forkserver._forkserver._preload_modules  # noqa: SLF001
    assert "hdrio.batch.worker_start" not in preload  # the process's own again


@pytest.mark.slow
def test_the_command_on_a_local_cluster_writes_what_the_serial_run_writes(
        write_brackets, tmp_path, capsys, monkeypatch):
    """``--dask local:2``: a cluster of its own, its workers forked, the fork server
    gone once the command is done."""
    pytest.importorskip("distributed", reason="Dask tests need the farm extra")
    import hdrio.batch.cluster as cluster

    shoot = tmp_path / "shoot"
    for letter in "abcd":
        write_brackets(LADDER, folder=shoot, size=(16, 24),
                       names=[f"pos_{letter}_1_{round(1 / t)}.png" for t in LADDER])
    forked = []
    server = cluster.fork_server

    def spy(*args, **kwargs):
        manager = server(*args, **kwargs)

        class Spy:
            def __enter__(self):
                forked.append(manager.__enter__())
                return forked[-1]

            def __exit__(self, *error):
                return manager.__exit__(*error)

        return Spy()

    monkeypatch.setattr(cluster, "fork_server", spy)
    serial, farm = tmp_path / "serial", tmp_path / "farm"
    assert main(["--threads", "1", str(shoot), "--group", "--merge",
                 "-o", f"{serial}/{{first_stem}}.exr"]) == 0
    assert _server_pid() is None
    assert main([str(shoot), "--dask", "local:2", "--group", "--merge",
                 "-o", f"{farm}/{{first_stem}}.exr"]) == 0, capsys.readouterr().err
    assert forked == [True] and _server_pid() is None

    def pixels(folder: Path) -> dict[str, np.ndarray]:
        return {p.name: read_image(p)[0] for p in sorted(folder.glob("*.exr"))}

    a, b = pixels(serial), pixels(farm)
    assert len(a) == 4 and a.keys() == b.keys()
    for name in a:  # same code on the same files: bit for bit
        np.testing.assert_array_equal(a[name], b[name])


@dataclass(frozen=True)
class Mark:
    """A set's work that takes a while and leaves a file named after the set."""

    folder: Path

    def __call__(self, task: SetTask) -> tuple[bool, str]:
        import time

        time.sleep(0.3)
        (self.folder / f"{task.index}.done").touch()
        return True, ""


def test_an_interrupted_pool_drops_the_sets_not_started(tmp_path):
    """Ctrl-C during ``--group``: the pool stops after the sets it is running, instead
    of going on through every set of the shoot while the command had already said
    'interrupted' (as it did). Interrupted at the first result, at most that set and
    one per worker can have run: the pool is handed a set only when a worker is free
    (when every set was queued at once, the pool's own queue started 7 of 12 on a
    loaded CI machine)."""
    tasks = [SetTask(index=k, files=(), times_s=(), fields={}, outputs=(), fingerprint="",
                     status="run") for k in range(1, 13)]

    def interrupt(result, done, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_local(tasks, Mark(tmp_path), workers=2, on_result=interrupt)
    assert 1 <= len(list(tmp_path.glob("*.done"))) <= 1 + 2
    assert _server_pid() is None


@dataclass(frozen=True)
class Dies:
    """A set's work whose worker dies (as the kernel's OOM killer ends it) at set
    ``index``: the first time only, or every time."""

    folder: Path
    index: int
    every_time: bool = False

    def __call__(self, task: SetTask) -> tuple[bool, str]:
        import signal
        import time

        marker = self.folder / "died"
        if task.index == self.index and (self.every_time or not marker.exists()):
            marker.touch()
            os.kill(os.getpid(), signal.SIGKILL)
        time.sleep(0.1)
        return True, ""


@pytest.mark.parametrize("every_time", [False, True])
def test_a_pool_worker_that_dies_loses_no_other_set(tmp_path, every_time):
    """A worker killed mid-set broke the whole pool: every set not finished failed with
    'internal error (BrokenProcessPool ...)' and the command stopped. Now the sets lost
    with it run again in a new pool; a set that kills its worker every time fails alone,
    saying so, and the others are done."""
    from hdrio.batch.pool import LOST

    tasks = [SetTask(index=k, files=(), times_s=(), fields={}, outputs=(), fingerprint="",
                     status="run") for k in range(1, 9)]
    results = run_local(tasks, Dies(tmp_path, 3, every_time), workers=2)
    assert sorted(r.index for r in results) == list(range(1, 9))
    failed = {r.index: r.printed for r in results if not r.ok}
    assert failed == ({3: LOST} if every_time else {})
    assert _server_pid() is None


def test_a_fork_server_that_cannot_start_leaves_spawned_workers(tmp_path, monkeypatch):
    def refuse():
        raise OSError("no socket here")

    monkeypatch.setattr(multiprocessing.forkserver._forkserver, "ensure_running", refuse)
    tasks = [SetTask(index=k, files=(), times_s=(), fields={}, outputs=(), fingerprint="",
                     status="run") for k in range(1, 3)]
    before = dict(os.environ)
    results = run_local(tasks, Report(os.getpid()), workers=2)
    assert all(r.ok and r.printed.startswith("False") for r in results)  # spawned
    assert dict(os.environ) == before and _server_pid() is None


@dataclass(frozen=True)
class Fill:
    """A set's work that says what its fork server was asked to compile."""

    def __call__(self, task: SetTask) -> tuple[bool, str]:
        from hdrio.jit import FILL_VARIABLE

        return True, os.environ.get(FILL_VARIABLE, "")


def test_the_fork_server_compiles_what_the_chain_needs_besides(tmp_path, monkeypatch):
    """A chain that tone-maps has its preview's kernels compiled by the fork server on a
    first run too (its environment says which); the command's own environment is left
    as it was."""
    from hdrio import jit

    tasks = [SetTask(index=k, files=(), times_s=(), fields={}, outputs=(), fingerprint="",
                     status="run") for k in range(1, 3)]
    before = dict(os.environ)
    results = run_local(tasks, Fill(), workers=2, fill=("preview=reinhard-global",))
    assert {r.printed for r in results} == {"preview=reinhard-global"}
    assert dict(os.environ) == before
    started = []

    class Process:
        def __init__(self, command, **_):
            started.append(command[command.index("hdrio.tools.precompile") + 1:])

        def wait(self):
            return 0

    monkeypatch.setattr(jit.subprocess, "Popen", Process)
    monkeypatch.setattr(jit, "is_stage_cached", lambda stage: False)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    assert jit.fill_cache(extra=["preview=reinhard-local"]) == [
        *jit.FILLED[0], "preview=reinhard-local", *jit.FILLED[1]]
    assert started == [[*jit.FILLED[0], "preview=reinhard-local"], [*jit.FILLED[1]]]
