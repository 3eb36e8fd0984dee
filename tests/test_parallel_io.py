"""The machine shared out: brackets decoded on every thread of the budget, the same
stack whatever the budget; OpenImageIO's and OpenEXR's pools and numba's sized to it; a
worker's environment that sizes every pool; the command ending without the
interpreter's teardown, its output and exit code intact."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from hdrio.io.brackets import read_brackets
from hdrio.io.staging import is_staged
from hdrio.io.write import rows_per_write, write_exr
from hdrio.parallel import BLAS_POOLS, threads, worker_environment

SEVEN = (1 / 256, 1 / 64, 1 / 16, 1 / 4, 1.0, 4.0, 16.0)


@pytest.mark.parametrize("budget", ["1", "2", "5", "16"])
def test_the_stack_does_not_depend_on_the_thread_budget(write_brackets, monkeypatch, budget):
    paths = write_brackets(SEVEN, size=(40, 56))
    monkeypatch.setenv("HDRIO_THREADS", "1")
    serial = read_brackets(paths[::-1])  # given in any order: sorted by exposure
    monkeypatch.setenv("HDRIO_THREADS", budget)
    parallel = read_brackets(paths[::-1])
    np.testing.assert_array_equal(parallel.codes, serial.codes)
    assert parallel.files == serial.files and parallel.kinds == serial.kinds
    np.testing.assert_array_equal(parallel.exposures, serial.exposures)


def test_staged_brackets_give_back_each_band_as_it_is_decoded(write_brackets,
                                                              monkeypatch):
    # Staged (a memory budget of 0) and decoded on 16 threads at once: every band's pages
    # are given back once written (9 x 24 MP brackets decoding at once held 9 x 72 MB
    # until each was whole: a merge's peak 846 MB at 16 threads, 566 MB at 2), and the
    # stack is the one decoded on one thread.
    import hdrio.io.brackets as brackets

    paths = write_brackets(SEVEN, size=(40, 56))
    monkeypatch.setenv("HDRIO_THREADS", "1")
    serial = read_brackets(paths)
    monkeypatch.setenv("HDRIO_THREADS", "16")
    monkeypatch.setenv("HDRIO_MEMORY_BUDGET_MB", "0")
    monkeypatch.setattr(brackets, "_ROWS_PER_READ", 8)
    given_back, release = [], brackets.release

    def recorded(codes, bracket=None, top=0, bottom=None):
        given_back.append((bracket, top, bottom))
        release(codes, bracket, top, bottom)

    monkeypatch.setattr(brackets, "release", recorded)
    parallel = read_brackets(paths)
    assert is_staged(parallel.codes)
    bands = {(top, top + 8) for top in range(0, 40, 8)}
    for position in range(len(SEVEN)):
        assert {(top, bottom) for j, top, bottom in given_back if j == position
                and bottom is not None} == bands
    np.testing.assert_array_equal(parallel.codes, serial.codes)
    assert parallel.kinds == serial.kinds


def test_brackets_beyond_an_all_dark_one_are_dropped_on_any_budget(write_brackets,
                                                                    monkeypatch):
    # The ramp is all dark at 2^-17 s and darker still below: both shorter brackets go,
    # each named with a reason that is true whether a thread decoded the shortest ahead
    # (it is all dark too) or not (one budget, one thread a side: never decoded).
    exposures = (2.0**-20, 2.0**-17, 1 / 16, 1 / 4, 1.0, 4.0)
    paths = write_brackets(exposures, size=(40, 56), names=[f"b{j}.png" for j in range(6)])
    for budget in ("1", "6"):
        monkeypatch.setenv("HDRIO_THREADS", budget)
        stack = read_brackets(paths, exposures=exposures)
        assert stack.count == 4, budget
        reasons = dict(stack.dropped)
        assert reasons[str(paths[1])] == "no well-exposed pixel (all dark)", reasons
        assert reasons[str(paths[0])] in (  # true whichever a thread got to first
            "shorter than an all-dark bracket: not decoded",
            "shorter than an all-dark bracket: decoded ahead, not used",
            "no well-exposed pixel (all dark)"), reasons


def test_a_bad_file_is_named_on_any_budget(write_brackets, monkeypatch, tmp_path):
    from hdrio.errors import InputError

    paths = write_brackets(SEVEN, size=(40, 56))
    paths[2].write_bytes(paths[2].read_bytes()[:200])  # truncated PNG
    monkeypatch.setenv("HDRIO_THREADS", "7")
    with pytest.raises(InputError, match=paths[2].name):
        read_brackets(paths)


def test_openimageio_pools_follow_the_budget(write_brackets, monkeypatch):
    import OpenImageIO as oiio

    paths = write_brackets(size=(16, 16))
    for budget in ("3", "1"):
        monkeypatch.setenv("HDRIO_THREADS", budget)
        read_brackets(paths)
        assert oiio.get_int_attribute("threads") == int(budget)
        assert oiio.get_int_attribute("exr_threads") == int(budget)


def test_the_exr_is_the_same_file_whatever_the_write_bands(tmp_path, monkeypatch):
    # Bands of 64 rows (one thread) or 256 (16 threads): OpenEXR compresses the same
    # 16-row blocks, so the file's bytes are the same.
    rng = np.random.default_rng(0)
    rgb = rng.gamma(2.0, 1.0, (700, 90, 3)).astype(np.float32)
    written = {}
    for budget in ("1", "16"):
        monkeypatch.setenv("HDRIO_THREADS", budget)
        assert rows_per_write() == 16 * max(4, int(budget))
        path = tmp_path / f"band{budget}.exr"
        # DateTime given: OpenImageIO would stamp the clock's second (capDate)
        write_exr(path, rgb, {"hdrio:units": "relative", "DateTime": "2026:01:01 00:00:00"})
        written[budget] = path.read_bytes()
    assert written["1"] == written["16"]


def test_a_worker_environment_sizes_every_pool():
    environment = worker_environment(3)
    assert environment["HDRIO_THREADS"] == environment["NUMBA_NUM_THREADS"] == "3"
    assert environment["OMP_NUM_THREADS"] == "3"
    assert environment["OPENBLAS_NUM_THREADS"] == environment["MKL_NUM_THREADS"] == "1"
    assert worker_environment(0)["HDRIO_THREADS"] == "1"


@pytest.mark.parametrize("exported", [None, "4"])
def test_the_command_keeps_blas_to_one_thread_unless_the_user_sized_it(monkeypatch,
                                                                      exported):
    import hdrio.__main__ as entry
    import hdrio.cli

    for name in BLAS_POOLS:
        monkeypatch.delenv(name, raising=False)
        if exported is not None:
            monkeypatch.setenv(name, exported)
    seen = {}
    monkeypatch.setattr(hdrio.cli, "run", lambda: seen.update(
        {name: os.environ.get(name) for name in BLAS_POOLS}))
    entry.run()
    assert seen == {name: exported or "1" for name in BLAS_POOLS}


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
@pytest.mark.parametrize("exported", [None, "8"])
def test_heap_arenas_are_limited_unless_the_user_chose(exported):
    # In a fresh process, as the command's entry and a pool worker's start call it; a
    # user's MALLOC_ARENA_MAX (which glibc read at start) is left as it is. Dask's local
    # workers get the variable in their environment.
    from hdrio.parallel import HEAP_ARENAS

    environment = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    if exported:
        environment["MALLOC_ARENA_MAX"] = exported
    printed = subprocess.run(
        [sys.executable, "-c", "from hdrio.parallel import limit_heap_arenas as l; "
                               "print(l())"], capture_output=True, text=True, check=True,
        env=environment).stdout.strip()
    assert printed == ("False" if exported else "True")
    assert worker_environment(2)["MALLOC_ARENA_MAX"] == str(HEAP_ARENAS)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_a_pool_worker_limits_its_heap_arenas_before_it_exports_the_variable():
    # The worker sets MALLOC_ARENA_MAX for its own children; asked after that, the limit
    # took the variable for the user's choice and was never applied in a pool worker.
    environment = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    script = ("import os\n"
              "import hdrio.batch.pool as pool, hdrio.parallel as parallel\n"
              "applied = []\n"
              "limit = parallel.limit_heap_arenas\n"
              "pool.limit_heap_arenas = lambda: applied.append(limit()) or applied[-1]\n"
              "pool._start_worker(os.getppid(), 2)\n"
              "print(applied, os.environ['MALLOC_ARENA_MAX'])\n")
    printed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                             check=True, env=environment).stdout.strip()
    assert printed == "[True] 4"


def test_numba_parallel_kernels_follow_the_budget(monkeypatch):
    import numba

    from hdrio.jit import size_numba_threads

    monkeypatch.setenv("HDRIO_THREADS", "1")
    size_numba_threads()
    assert numba.get_num_threads() == 1
    monkeypatch.setenv("HDRIO_THREADS", str(max(1, threads())))
    size_numba_threads()
    assert numba.get_num_threads() == min(threads(), numba.config.NUMBA_NUM_THREADS)


def test_the_command_ends_with_its_output_and_exit_code(tmp_path, brackets):
    # python -m hdrio ends through os._exit after flushing: output redirected to a file
    # (block-buffered) is whole, and the exit code is the command's.
    out = tmp_path / "stdout.txt"
    with out.open("w") as stdout:
        done = subprocess.run([sys.executable, "-m", "hdrio", "merge", *map(str, brackets),
                               "-o", str(tmp_path / "m.exr")], stdout=stdout,
                              stderr=subprocess.PIPE, text=True,
                              env={**os.environ, "HDRIO_THREADS": "2"})
    assert done.returncode == 0, done.stderr
    text = out.read_text()
    assert "wrote:" in text and "check:" in text and text.endswith("\n")
    refused = subprocess.run([sys.executable, "-m", "hdrio", "merge", str(brackets[0]),
                              "-o", str(tmp_path / "one.exr")], capture_output=True,
                             text=True)
    assert refused.returncode == 2 and "error" in refused.stderr
