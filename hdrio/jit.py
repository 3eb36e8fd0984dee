"""The first run after install: saying that kernels compile, and compiling on two cores.

Kernels compile on first use and are cached on disk (``cache=True``); a later process
loads them in milliseconds. The first run of a job can spend most of its time compiling,
so the pipeline announces it: "compiling kernels (first run only)". numba compiles on one
thread, so a first ``hdrio merge`` or ``hdrio demo`` also starts processes
(:func:`compile_ahead`, running :mod:`hdrio.tools.precompile`) that compile kernels the job
needs later (the merge's, the preview's tone mapping, and with four CPUs or more
alignment's and deghosting's, which on fewer this process compiles itself when it
reaches them) while this one reads the brackets and solves the response; it waits for
them before those stages and then loads those kernels from the cache. Rather than wait
idle, it first compiles the stages it would compile itself later (:func:`announce`).

**Slice copies.** A kernel copies one array into another element by element, never as
``out[a:b] = values`` (or ``+=``): numba compiles every array-to-slice assignment with a
shape check whose error message it formats with f-strings, and compiling that string
machinery cost a first run 4.3 s of CPU in the merge kernel alone (its compile 17.6 ->
12.7 s). A scalar assigned to a slice (``out[:] = 0.0``) has no such check.
``tests/test_kernel_source.py`` scans every kernel's source for the pattern.
"""

from __future__ import annotations

import contextlib
import importlib
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator, Sequence

INNER = {"no_cpython_wrapper": True, "no_cfunc_wrapper": True}
"""numba options of a kernel's helper that only other kernels call (``@njit(...,
**INNER)``, without ``cache=True``): no Python or C entry point of its own to build (each
costs about 0.05 s of a first run's compile), and no cache file of its own to write; a
cached kernel holds the code of every helper it calls. Such a helper cannot be called
from Python."""

_warming: threading.Thread | None = None
"""The thread :func:`warm_up` started in this process (None before)."""


def warm_up(*modules: str) -> None:
    """Prepare, on a background thread, what a merge's later stages load on first use:
    numba's CPU target, then ``modules`` (imported). Once per process; nothing on one
    CPU.

    The first kernel a process calls, even one loaded from the disk cache, first imports
    and registers numba's lowering of NumPy (measured here: the first cached kernel
    0.98-1.03 s, the next 0.01 s), and deghosting's first use of ``scipy.ndimage``
    imports it (0.6 s, most of it SciPy parsing docstrings). A merge starts this when it
    begins reading the brackets, while its main thread waits on the decoders (which
    release the GIL), so that on a machine with cores to spare both are done before the
    stages need them. numba's part runs under its compiler lock (a kernel called
    meanwhile waits for it), an import under Python's import lock."""
    global _warming
    from hdrio.parallel import threads

    if _warming is not None or threads() < 2:
        return

    def prepare() -> None:
        prepare_numba()
        for module in modules:
            with contextlib.suppress(ImportError):
                importlib.import_module(module)

    _warming = threading.Thread(target=prepare, name="hdrio-warm-up", daemon=True)
    _warming.start()


def prepare_numba() -> None:
    """Load what the first kernel of a process loads, even one from the disk cache:
    numba's CPU target, its lowering of NumPy registered (about 1 s, :func:`warm_up`).
    Runs under numba's compiler lock; nothing when numba's internals moved (the first
    kernel then does it)."""
    try:
        from numba.core.compiler_lock import global_compiler_lock
        from numba.core.registry import cpu_target

        with global_compiler_lock:
            cpu_target.target_context.refresh()
    except Exception:  # noqa: BLE001 - numba's internals moved: the first kernel does it
        pass


def size_numba_threads() -> None:
    """numba's parallel kernels (``parallel=True``) on this process's budget
    (:func:`hdrio.parallel.threads`) rather than on every CPU of the machine: called
    before each such kernel, since a farm worker's budget is a share of the machine."""
    import numba

    from hdrio.parallel import threads

    numba.set_num_threads(max(1, min(threads(), numba.config.NUMBA_NUM_THREADS)))


STAGES: dict[str, tuple[str, ...]] = {
    "merge": ("hdrio.merge.kernel:merge_rows_by_pairs", "hdrio.radiometry.noise_fit:_clipped_near",
              "hdrio.io.half:_to_half_values", "hdrio.cms.check_counts:count_pixels"),
    "motion": ("hdrio.align.quick:_read", "hdrio.align.consistency:_consistency"),
    "preview": ("hdrio.tonemap.reinhard2002_kernels:_global_blocks",),
    "response": ("hdrio.radiometry.cliptest:_flag_grid",),
}
"""The kernels whose cache stands for each stage's (they compile together). Motion's are
the still check's and deghosting's, what ``auto`` runs on most stacks; registering a stack
that moved compiles more (the base image, Lucas-Kanade) on first use, unannounced."""


def _dispatcher(name: str):
    module, _, attribute = name.partition(":")
    return getattr(importlib.import_module(module), attribute)


def is_cached(dispatcher) -> bool:
    """True when ``dispatcher`` (a numba ``cache=True`` function) is compiled in this
    process or has an index in the disk cache; True when that cannot be told."""
    if getattr(dispatcher, "signatures", None):
        return True
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if cache_file is None:
        return True
    try:  # numba's IndexDataCacheFile: {} when missing or stale (source changed)
        return bool(cache_file._load_index())
    except Exception:  # numba internals moved: do not claim a compile we cannot see
        return True


def announce(say: Callable[[str], None], stage: str) -> None:
    """Say "compiling kernels (first run only): STAGE" when ``stage``'s kernels (a key of
    :data:`STAGES`) are not in the cache yet (after waiting for :func:`compile_ahead`'s
    process of that stage); the progress log times each stage.

    Where that process has not finished yet, this one first compiles the stages it would
    compile itself later (:data:`_own`) rather than wait idle: on 2 cores ``hdrio demo``
    waited 1.5 s for the merge's kernels and then compiled the preview's for 2.4 s."""
    if _own and _busy(stage):
        for own in _own:
            name = own.partition("=")[0]
            if not is_stage_cached(name):
                say(f"compiling kernels (first run only): {name}, while the {stage}'s "
                    "compile ends; later runs load them from the cache")
                _compile_here(own)
        _own.clear()
    _wait_for(stage)
    if not is_stage_cached(stage):
        say(f"compiling kernels (first run only): {stage}; later runs load them from the "
            "cache")


_LATER_NICENESS = (0, 4, 8)
"""Niceness of the compile-ahead processes for motion, merge and preview when each has
a process of its own (CFS gives a process of niceness 4 about 40 % of a nice-0 one's
share)."""

ONE_HELPER_BELOW = 4
"""With fewer CPUs than this, :func:`compile_ahead` starts one process, for the merge,
and this process compiles alignment's and deghosting's kernels itself when it reaches
them, and then the preview's (while it waits for the helper's merge, :func:`announce`):
on 2 cores a first run is CPU-bound, and each process more costs its imports (0.8 s of
CPU) for no core of its own. (With the preview in the helper too, after the merge,
``hdrio demo`` waited 2.2 s for it at the end with a core idle; without a motion stage
to compile, the helper still does both.)"""

_pending: dict[str, subprocess.Popen] = {}
"""Processes of :func:`compile_ahead` by the stage they compile for."""

_finished: set[str] = set()
"""Stages a process of :func:`compile_ahead` said it has compiled."""

_own: list[str] = []
"""Stages (:mod:`hdrio.tools.precompile` names) that :func:`compile_ahead` gave no process
and that the job reaches after the merge (the preview's on 2-3 CPUs): :func:`announce`
compiles them here while a helper's stage is still compiling, else they compile on first
use."""


def _busy(stage: str) -> bool:
    """True when a process of :func:`compile_ahead` is compiling ``stage`` and has not said
    it is done (nothing to read from it yet); False where that cannot be told."""
    process = _pending.get(stage)
    if process is None or stage in _finished:
        return False
    try:
        import select

        ready, _, _ = select.select([process.stdout], [], [], 0)
    except (OSError, ValueError, TypeError):  # e.g. Windows: select takes sockets only
        return False
    return not ready


def _compile_here(stage: str) -> None:
    """Compile ``stage`` (a :mod:`hdrio.tools.precompile` name) in this process. A failure
    is left for the stage's first real use to raise, with the job's own data."""
    try:
        importlib.import_module("hdrio.tools.precompile").compile_stage(stage)
    except Exception:  # noqa: BLE001 - the real call compiles again and says why
        pass


def helper_jobs(cpus: int, stages: list[str]) -> list[tuple[int, list[str]]]:
    """The compile-ahead processes for ``stages`` (names of :mod:`hdrio.tools.precompile`:
    ``motion``, ``merge``, ``preview=OPERATOR``, in the order the job needs them) on
    ``cpus`` CPUs: ``(niceness, stages)`` each. Below :data:`ONE_HELPER_BELOW` CPUs, one
    process of the merge (the job compiles motion's kernels itself, and then the
    preview's), or of the merge and the preview when there is no motion stage to compile;
    else one process a stage, each later one at a lower priority (the stage the job
    waits for next should not share its core with one it needs seconds later)."""
    if cpus < ONE_HELPER_BELOW:
        here = {"motion", "preview"} if "motion" in stages else {"motion"}
        ahead = [stage for stage in stages if stage.partition("=")[0] not in here]
        return [(0, ahead)] if ahead else []
    by_stage = {stage.partition("=")[0]: stage for stage in stages}
    return [(niceness, [by_stage[name]])
            for niceness, name in zip(_LATER_NICENESS, ("motion", "merge", "preview"),
                                      strict=True) if name in by_stage]


def compile_ahead(preview: str | None, merge: Callable[[], bool], motion: bool = False
                  ) -> None:
    """On a first run, start processes (:mod:`hdrio.tools.precompile`) compiling kernels into
    the disk cache: the merge kernel of 8-bit RGB brackets when ``merge()`` (asked only
    when a kernel is not cached), with ``motion`` alignment's still check and
    deghosting's test of such brackets, and the ``preview`` operator's (a
    ``TONEMAP_METHODS`` name, or None); how many processes: :func:`helper_jobs`.
    Nothing when they are cached already, being compiled, or this process may use one
    CPU only.
    :func:`announce` of a stage waits for the process compiling it first."""
    from hdrio.parallel import threads

    cpus = threads()
    if cpus < 2:
        return
    uncached = [stage for stage in ("motion", "merge")
                if (motion or stage == "merge") and not _started_or_cached(stage)]
    if uncached and not merge():  # their kernels are compiled for 8-bit RGB brackets
        uncached = []
    if preview and not _started_or_cached("preview"):
        uncached.append(f"preview={preview}")
    jobs = helper_jobs(cpus, uncached)
    helped = {name for _, names in jobs for name in names}
    _own[:] = [stage for stage in uncached
               if stage not in helped and stage.partition("=")[0] != "motion"]
    for niceness, names in jobs:
        process = subprocess.Popen([sys.executable, "-m", "hdrio.tools.precompile",
                                    f"nice={niceness}", *names],
                                   stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                   stderr=subprocess.DEVNULL, text=True)
        _pending.update((name.partition("=")[0], process) for name in names)


FILLED = (("response", "motion"), ("merge",))
"""The stages :func:`fill_cache` compiles, in two processes: what ``auto`` runs on most
stacks. (The job's own compile-ahead has no response stage: the job needs its kernel
before a helper could have imported numba.)"""


FILL_VARIABLE = "HDRIO_FILL"
"""Stages a batch's fork server compiles besides :data:`FILLED` (comma-separated
:mod:`hdrio.tools.precompile` names, e.g. ``preview=reinhard-global`` when the chain
tone-maps): set in the server's environment only (:func:`hdrio.batch.pool.fork_server`)."""


def fill_cache(extra: Sequence[str] = ()) -> list[str]:
    """Compile the stages of :data:`FILLED` (``NAME`` or ``NAME=VALUE`` of
    :mod:`hdrio.tools.precompile`, ``NAME`` a key of :data:`STAGES`) whose kernels are not
    cached, into the disk cache, a process a group (:mod:`hdrio.tools.precompile`), all
    at once; return once they are done, with the stages compiled. What a batch's fork
    server does before it forks the workers, and a Dask worker started with ``--preload
    hdrio.batch.worker_start``: each worker then loads the kernels instead of compiling
    them all again. This process compiles nothing and starts no thread. ``extra``
    stages join the first group.

    Processes of one user on one machine take turns (a lock file in the temporary
    folder, where ``fcntl`` has locks): eight workers started at once on a fresh node
    compile once, and the other seven find the kernels cached."""
    groups = ((*FILLED[0], *extra), *FILLED[1:])
    with _machine_lock("fill-cache"):
        todo = [[stage for stage in group if not is_stage_cached(stage.partition("=")[0])]
                for group in groups]
        processes = [subprocess.Popen(
            [sys.executable, "-m", "hdrio.tools.precompile", *group],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for group in todo if group]
        for process in processes:
            process.wait()
    return [stage for group in todo for stage in group]


@contextlib.contextmanager
def _machine_lock(name: str) -> Iterator[None]:
    """Held by one process of this user on this machine at a time (``flock`` on
    ``hdrio-UID-NAME.lock`` in the temporary folder); no lock where there is no
    ``fcntl`` (Windows) or the file cannot be opened."""
    import os
    import tempfile

    try:
        import fcntl
    except ImportError:
        yield
        return
    user = os.getuid() if hasattr(os, "getuid") else "user"
    path = os.path.join(tempfile.gettempdir(), f"hdrio-{user}-{name}.lock")
    try:
        handle = open(path, "a")  # noqa: SIM115 - held open for the lock's lifetime
    except OSError:
        yield
        return
    with handle:  # closing it gives the lock back
        fcntl.flock(handle, fcntl.LOCK_EX)
        yield


def _started_or_cached(stage: str) -> bool:
    """True when a process of :func:`compile_ahead` compiles or compiled ``stage``, or its
    kernels are cached (a second call, e.g. ``hdrio demo``'s before rendering and the
    merge's, starts nothing twice)."""
    return stage in _pending or stage in _finished or is_stage_cached(stage)


def _wait_for(stage: str) -> None:
    """Wait until :func:`compile_ahead`'s process for ``stage`` says it has compiled it
    (its kernels are then in the cache), or ends (if it failed, they simply compile here
    on first use)."""
    process = _pending.pop(stage, None)
    while process is not None and stage not in _finished:
        line = process.stdout.readline()
        if not line:
            process.wait()
            break
        _finished.add(line.strip())
    if process is not None and process not in _pending.values():
        process.wait()  # its last stage: it exits now


def is_stage_cached(stage: str) -> bool:
    """True when every kernel standing for ``stage`` (a key of :data:`STAGES`) is cached."""
    return all(is_cached(_dispatcher(name)) for name in STAGES[stage])
