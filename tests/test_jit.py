"""First run: kernels compiled ahead in a helper process land in the disk cache that the
job then loads (it does not compile them a second time)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import pytest

from hdrio import jit
from hdrio.parallel import threads

# Slow (compiles every kernel in fresh processes with an empty cache): deselected by
# default, run by `pytest -m slow` (CI runs both).
pytestmark = pytest.mark.slow

_CACHED = """
import sys
from hdrio import jit
print(" ".join(f"{stage}={jit.is_stage_cached(stage)}" for stage in sys.argv[1:]))
"""


def _run(code_or_module: list[str], cache: str) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    return subprocess.run([sys.executable, *code_or_module], capture_output=True, text=True,
                          env=env, check=True, timeout=600).stdout.strip()


def test_compile_ahead_fills_the_cache_the_job_reads(tmp_path):
    cache = str(tmp_path / "numba-cache")
    stages = ["merge", "motion", "preview"]
    assert _run(["-c", _CACHED, *stages], cache) == "merge=False motion=False preview=False"
    said = _run(["-m", "hdrio.tools.precompile", "merge", "motion", "preview=reinhard-global"],
                cache)
    assert said.split() == stages  # each stage's name once it is cached (hdrio.jit waits on it)
    # A new process finds every kernel of those stages in the cache: the job's merge,
    # alignment, deghosting and preview load them instead of compiling.
    assert _run(["-c", _CACHED, *stages], cache) == "merge=True motion=True preview=True"


def test_a_first_merge_says_it_compiles_only_what_is_not_cached(tmp_path, brackets):
    cache = str(tmp_path / "numba-cache")
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    command = [sys.executable, "-m", "hdrio", "merge", *map(str, brackets), "-o",
               str(tmp_path / "out.exr"), "--preview", str(tmp_path / "out.jpg")]
    first = subprocess.run(command, capture_output=True, text=True, env=env, timeout=900)
    assert first.returncode == 0, first.stderr
    # The kernels of the stages compiled ahead (on this machine's CPUs) were compiled
    # meanwhile by the helper processes, so the job loads them and says nothing of them;
    # the others it compiles (and says so). The response's solve and the report's check
    # are NumPy: nothing to compile.
    ahead = {name.partition("=")[0] for _, names in
             jit.helper_jobs(threads(), ["motion", "merge", "preview=reinhard-global"])
             for name in names}
    assert "compiling kernels (first run only): response" not in first.stderr
    for stage in ("merge", "motion", "preview"):
        said = f"compiling kernels (first run only): {stage}" in first.stderr
        assert said == (stage not in ahead), (stage, first.stderr)
    second = subprocess.run(command, capture_output=True, text=True, env=env, timeout=900)
    assert second.returncode == 0 and "compiling kernels" not in second.stderr


def test_two_cpus_compile_ahead_in_one_process_and_more_in_one_a_stage():
    stages = ["motion", "merge", "preview=reinhard-local"]
    # On 2 or 3 CPUs: one process, at full priority, for the merge; the job compiles
    # alignment's and deghosting's kernels itself (a process more would cost its imports
    # and have no core of its own), and then the preview's. Without a motion stage to
    # compile, the process does the merge and then the preview.
    assert jit.helper_jobs(2, stages) == [(0, ["merge"])]
    assert jit.helper_jobs(2, stages[1:]) == [(0, ["merge", "preview=reinhard-local"])]
    assert jit.helper_jobs(3, ["motion"]) == []
    # On 4 or more: a process a stage, later stages at a lower priority.
    assert jit.helper_jobs(4, stages) == [(0, ["motion"]), (4, ["merge"]),
                                          (8, ["preview=reinhard-local"])]
    assert jit.helper_jobs(8, ["merge", "preview=reinhard-global"]) == [
        (4, ["merge"]), (8, ["preview=reinhard-global"])]


def test_a_second_compile_ahead_starts_nothing_already_started(monkeypatch):
    # `hdrio demo` starts compiling before it renders its brackets, and merge_files asks
    # again: stages being compiled (or compiled) by a process are not started twice.
    started = []

    class _Process:
        def __init__(self, command, **_):
            started.append(command[command.index("hdrio.tools.precompile") + 2:])

    monkeypatch.setattr(jit.subprocess, "Popen", _Process)
    monkeypatch.setattr(jit, "_pending", {})
    monkeypatch.setattr(jit, "_finished", set())
    monkeypatch.setattr(jit, "is_stage_cached", lambda stage: False)
    monkeypatch.setenv("HDRIO_THREADS", "2")
    jit.compile_ahead("reinhard-global", merge=lambda: True, motion=True)
    jit.compile_ahead("reinhard-global", merge=lambda: True, motion=True)
    assert started == [["merge"]]  # on 2 CPUs the job compiles motion, then the preview
    jit._pending.pop("merge")
    jit._finished.add("merge")  # said by the process, waited for
    jit.compile_ahead("reinhard-local", merge=lambda: True)  # no motion stage to compile
    assert started == [["merge"], ["preview=reinhard-local"]]
    jit.compile_ahead("reinhard-local", merge=lambda: True)
    assert started == [["merge"], ["preview=reinhard-local"]]


class _Helper:
    """A compile-ahead process as :mod:`hdrio.jit` sees it: a pipe it prints stage names to."""

    def __init__(self):
        read, self.write = os.pipe()
        self.stdout = os.fdopen(read)

    def say(self, stage):
        os.write(self.write, f"{stage}\n".encode())

    def wait(self):
        return 0

    def close(self):
        self.stdout.close()
        os.close(self.write)


@pytest.mark.skipif(sys.platform.startswith("win"), reason="select() takes sockets only")
@pytest.mark.parametrize("helper_done_first", [False, True])
def test_the_job_compiles_its_own_later_stage_while_a_helper_is_still_compiling(
        monkeypatch, helper_done_first):
    # On 2 CPUs the helper compiles the merge and the job the preview. A job that reaches
    # the merge before the helper is done compiles the preview first (it waited idle for
    # 1.5 s, then compiled the preview for 2.4 s); one that finds the helper done does not.
    helper, compiled, said = _Helper(), [], []
    monkeypatch.setattr(jit, "_pending", {"merge": helper})
    monkeypatch.setattr(jit, "_finished", set())
    monkeypatch.setattr(jit, "_own", ["preview=reinhard-global"])
    monkeypatch.setattr(jit, "is_stage_cached",
                        lambda stage: stage in compiled or stage in jit._finished)

    def compile_here(stage):
        compiled.append(stage.partition("=")[0])
        helper.say("merge")  # the helper finishes meanwhile

    monkeypatch.setattr(jit, "_compile_here", compile_here)
    # Should the job wait without compiling, the helper still ends (and the test fails).
    timer = threading.Timer(2.0, helper.say, ["merge"])
    if helper_done_first:
        helper.say("merge")
    else:
        timer.start()
    jit.announce(said.append, "merge")
    timer.cancel()
    helper.close()
    assert compiled == ([] if helper_done_first else ["preview"])
    assert "merge" in jit._finished
    assert jit._own == (["preview=reinhard-global"] if helper_done_first else [])
    assert said == ([] if helper_done_first else [
        "compiling kernels (first run only): preview, while the merge's compile ends; "
        "later runs load them from the cache"])


_WARM_UP = """
import os, sys
from hdrio import jit
jit.warm_up("colorsys")
thread = jit._warming
if thread is None:
    print("none")
else:
    thread.join()
    from numba.core.registry import cpu_target
    # numba's NumPy lowering registered, the module imported, by the background thread
    print("colorsys" in sys.modules, len(cpu_target.target_context._registries) > 5)
jit.warm_up("colorsys")
print(jit._warming is thread)
"""


@pytest.mark.parametrize("budget", ["1", "2"])
def test_the_warm_up_prepares_numba_and_imports_once_on_two_cpus_or_more(budget):
    # A fresh process: the warm-up is once per process, and on one CPU nothing (a second
    # thread would only take turns with the first).
    printed = subprocess.run([sys.executable, "-c", _WARM_UP], capture_output=True,
                             text=True, check=True,
                             env={**os.environ, "HDRIO_THREADS": budget}).stdout.split()
    assert printed == (["none", "True"] if budget == "1" else ["True", "True", "True"])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="workers are forked on Linux")
def test_a_first_batch_compiles_once_before_its_workers_start(tmp_path, write_brackets):
    """``--group`` on two workers with an empty cache: their fork server compiles the
    merge's and the motion stage's kernels into the cache once (hdrio.jit.fill_cache,
    each stage in a process of its own) and says so; each worker then loads them, where
    before each compiled them all itself (8 sets of 7 x 3 MP here: 16.0 s and 31 CPU
    seconds, now 11.8-12.0 s and 20.6; on that JPEG shoot the cache after the run was
    the cache after the fill). A second run says nothing of compiling, nor compiles."""
    cache = tmp_path / "numba-cache"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "HDRIO_THREADS": "2"}
    shoot = tmp_path / "shoot"
    for letter in "ab":
        write_brackets((1 / 64, 1 / 16, 1 / 4), folder=shoot, size=(16, 24),
                       names=[f"{letter}_1_{d}.png" for d in (64, 16, 4)])
    command = [sys.executable, "-m", "hdrio", "--threads", "2", str(shoot), "--group",
               "--merge", "-o", str(tmp_path / "hdr" / "{first_stem}.exr")]
    first = subprocess.run(command, capture_output=True, text=True, env=env, timeout=900)
    assert first.returncode == 0, first.stderr
    said = "compiling kernels (first run only), once before the workers start"
    assert said in first.stdout + first.stderr
    filled = sorted(path.name for path in cache.rglob("*.nbi"))
    stages = [stage for group in jit.FILLED for stage in group]
    assert _run(["-c", _CACHED, *stages], str(cache)) == " ".join(
        f"{stage}=True" for stage in stages)
    second = subprocess.run(command, capture_output=True, text=True, env=env, timeout=900)
    assert second.returncode == 0 and said not in second.stdout + second.stderr
    assert sorted(path.name for path in cache.rglob("*.nbi")) == filled


@pytest.mark.skipif(sys.platform.startswith("win"), reason="fcntl's locks")
def test_workers_starting_at_once_on_a_fresh_node_compile_once(tmp_path):
    """Two processes fill an empty cache at the same moment (as the workers of ``dask
    worker --nworkers N --preload hdrio.batch.worker_start`` do on a fresh node): one
    compiles every stage, the other waits for it and finds them all cached."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache"),
           "TMPDIR": str(tmp_path)}  # the lock file's folder, this test's own
    code = "from hdrio import jit; print(jit.fill_cache())"
    processes = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                                  text=True, env=env) for _ in range(2)]
    said = sorted(process.communicate(timeout=600)[0].strip() for process in processes)
    assert all(process.returncode == 0 for process in processes)
    stages = [stage for group in jit.FILLED for stage in group]
    assert said == sorted(["[]", repr(stages)])
