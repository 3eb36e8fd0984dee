"""Run sets: the per-set wrapper every executor uses, and the local process pool.

:func:`run_set` is what runs in a worker, whichever executor started it: it runs the
front end's ``work`` on one set, checks that every output is in place, and then records
the set in the journal (:mod:`hdrio.batch.journal`), so a set is recorded by the process
that finished it even if the process that started the batch is gone.

On Linux the pool's workers are forked from a fork server that has already imported what
a set needs and loaded numba's CPU target (:mod:`hdrio.batch.worker_start`, and the
module of the work), so a worker starts without paying those imports and that load
(about 1.1 s of CPU a worker here) itself; on a first run the server also compiles the
common kernels into the cache once. It is started with the workers' environment
(:func:`hdrio.parallel.worker_environment`), which numba and OpenMP read when they load,
and stopped when the pool is done (so the workers' CPU time is counted to ``hdrio``,
their parent's parent). Elsewhere workers are spawned.

Pool workers die with their parent: on Linux through ``PR_SET_PDEATHSIG`` (the kernel
sends SIGKILL when the parent dies; a fork server exits when ``hdrio`` does), and
everywhere through a thread that polls the parent's process id, so a killed ``hdrio``
leaves no worker behind.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import socket
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass

from hdrio.batch.journal import record_done
from hdrio.batch.partial import clean_partials
from hdrio.batch.tasks import SetTask
from hdrio.jit import FILL_VARIABLE
from hdrio.parallel import die_with_parent, limit_heap_arenas, worker_environment

Work = Callable[[SetTask], tuple[bool, str]]
OnResult = Callable[["SetResult", int, int], None]


@dataclass(frozen=True)
class SetResult:
    """What became of one set.

    Attributes
    ----------
    index : int
        The set's index (:attr:`SetTask.index`).
    ok : bool
        Every output written and the set recorded.
    printed : str
        What the work printed (the error on failure).
    host, pid :
        Where it ran.
    seconds : float
        Wall time of the set, in seconds.
    peak_rss_mb : float
        Peak resident memory of the worker process so far, in MiB.
    """

    index: int
    ok: bool
    printed: str
    host: str
    pid: int
    seconds: float
    peak_rss_mb: float


def _peak_rss_mb() -> float:
    """This process's peak resident memory in MiB: ``VmHWM`` on Linux (``ru_maxrss``
    carries a parent's peak over fork and exec), else ``ru_maxrss``."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    try:
        import resource
    except ImportError:  # Windows
        return float("nan")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 1024.0**2 if sys.platform == "darwin" else peak / 1024.0


def run_set(work: Work, task: SetTask) -> SetResult:
    """Run ``work(task)`` and record the set when it succeeded (in the worker).

    First the stale temporary files of this host in the set's output folders are removed
    (:mod:`hdrio.batch.partial`): on a cluster, each machine cleans its own.
    """
    start = time.perf_counter()
    clean_partials({path.parent for path in task.outputs})
    try:
        ok, printed = work(task)
    except Exception as error:  # one set's failure must not stop the others
        ok, printed = False, f"error: {type(error).__name__}: {error}\n"
    if ok:
        missing = [str(path) for path in task.outputs if not path.is_file()]
        if missing:
            ok, printed = False, printed + f"error: not written: {', '.join(missing)}\n"
        else:
            record_done(task.outputs, task.fingerprint, task.files)
    return SetResult(task.index, ok, printed, socket.gethostname(), os.getpid(),
                     time.perf_counter() - start, _peak_rss_mb())


def worker_threads(workers: int) -> int:
    """Kernel threads per worker when ``workers`` share this machine's CPUs."""
    from hdrio.parallel import threads

    return max(1, threads() // max(1, workers))


WORKER_START = "hdrio.batch.worker_start"
"""The module a fork server imports before it forks pool workers."""


def _start_worker(parent_pid: int, threads: int, forked: bool = False) -> None:
    die_with_parent(parent_pid, forked)
    # Before the variables below: MALLOC_ARENA_MAX set by them would read as the user's
    # own choice, and glibc has read the environment already (before the merge's threads).
    limit_heap_arenas()
    for name, value in worker_environment(threads).items():
        os.environ.setdefault(name, value)


def run_local(tasks: Sequence[SetTask], work: Work, workers: int,
              on_result: OnResult | None = None, fill: Sequence[str] = ()
              ) -> list[SetResult]:
    """Run ``tasks`` in a pool of ``workers`` processes on this machine (one: serially,
    in this process).

    ``on_result(result, done, total)`` is called in this process as each set finishes.
    Results are returned in the order the sets finished. A worker that dies (killed, out
    of memory) loses no other set: the sets it took down with the pool run again in a
    new one (:data:`LOST`). ``fill``: stages the fork server compiles on a first run
    besides the common ones (:data:`hdrio.jit.FILL_VARIABLE`).
    """
    if not tasks:
        return []
    workers = max(1, min(workers, len(tasks)))
    results = []
    if workers == 1:  # serial: in this process, without a pool's start-up (seconds)
        for task in tasks:
            results.append(run_set(work, task))
            if on_result is not None:
                on_result(results[-1], len(results), len(tasks))
        return results
    share = worker_threads(workers)
    with fork_server(share, WORKER_START, work_module(work), fill=fill) as forked:
        context = multiprocessing.get_context("forkserver" if forked else "spawn")
        start = (os.getpid(), share, forked)
        left = list(tasks)
        while left:  # a worker died: what its pool had not finished, in a new pool
            done = len(results)
            left = _pool_round(left, work, workers, context, start, results, on_result,
                               len(tasks))
            if left and len(results) == done:  # none finished: a set kills its worker
                for task in left:  # find it: a set a pool, one after another
                    if _pool_round([task], work, 1, context, start, results, on_result,
                                   len(tasks)):
                        results.append(SetResult(task.index, False, LOST,
                                                 socket.gethostname(), 0, 0.0, float("nan")))
                        if on_result is not None:
                            on_result(results[-1], len(results), len(tasks))
                left = []
    return results


LOST = ("error: its worker died while running it (killed, or out of memory?), also "
        "when it ran alone; a rerun of the command tries it again\n")
"""What a set says whose worker died under it even when it ran in a pool of its own.
When a pool worker dies, the pool breaks and every set it had not finished is lost with
it: those run again in a new pool, round after round while a round finishes some; when
one finishes none, each set left runs in a pool of its own, and those that kill it
again fail with this."""


def _pool_round(tasks: list[SetTask], work: Work, workers: int,
                context: multiprocessing.context.BaseContext, start: tuple,
                results: list[SetResult], on_result: OnResult | None, total: int
                ) -> list[SetTask]:
    """Run ``tasks`` in a new pool, appending each finished set's result to ``results``
    (and telling ``on_result``); return the sets lost with a worker that died."""
    pool = ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=context,
                               initializer=_start_worker, initargs=start)
    waiting = list(reversed(tasks))
    running: dict = {}
    lost = []

    def start_next() -> None:
        if waiting:
            try:
                running[pool.submit(run_set, work, waiting[-1])] = waiting[-1]
            except BrokenProcessPool:  # a worker died just now: its set says so next
                return
            waiting.pop()

    try:
        # A set is handed to the pool only when a worker is free for it, never queued
        # ahead: on Ctrl-C (or an error in on_result) only the sets already running
        # finish. Submitting every set at once let the pool's own queue start more
        # after the interrupt, how many depending on timing.
        for _ in range(workers):
            start_next()
        while running:
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                task = running.pop(future)
                try:
                    result = future.result()
                except BrokenProcessPool:  # the pool is gone: nothing more starts in it
                    lost.append(task)
                    continue
                if not lost:
                    start_next()
                results.append(result)
                if on_result is not None:
                    on_result(result, len(results), total)
        lost.extend(waiting)
    finally:
        # Interrupted (Ctrl-C) or failed: the running sets finish (or stop, when the
        # workers were interrupted too); the others were never handed to the pool.
        pool.shutdown(wait=True, cancel_futures=True)
    return sorted(lost, key=lambda task: task.index)


def forks_workers() -> bool:
    """Whether :func:`fork_server` would start a fork server now (Linux, and none of
    this process's running)."""
    import multiprocessing.forkserver as forkserver

    server = forkserver._forkserver  # noqa: SLF001
    return (sys.platform.startswith("linux") and hasattr(server, "_stop")
            and getattr(server, "_forkserver_pid", None) is None)


def work_module(work: Work) -> str:
    """The module that defines ``work`` (a function, a ``functools.partial`` of one, or
    a callable object): what a worker imports to unpickle it."""
    function = getattr(work, "func", work)
    module = getattr(function, "__module__", None)
    return module if isinstance(module, str) else type(function).__module__


@contextlib.contextmanager
def fork_server(threads: int, *modules: str, fill: Sequence[str] = ()) -> Iterator[bool]:
    """A fork server of this process's own for worker processes of ``threads`` threads
    each, with ``modules`` imported before it forks any: True inside when it runs (start
    the workers with the ``forkserver`` context), False where workers must be spawned.

    On Linux only, and only when this process runs no fork server yet (one started with
    another share of threads would hand its workers the wrong sizes). It starts with the
    workers' environment (:func:`hdrio.parallel.worker_environment`, the user's own
    values standing), which numba, OpenMP and glibc read when they load (and ``fill``,
    stages to compile on a first run: :data:`hdrio.jit.FILL_VARIABLE`), and is stopped
    and waited for on leaving, after its workers are gone. Not this process itself
    forked: OpenImageIO and numba keep thread pools that a fork would copy mid-flight;
    the server has started none."""
    import multiprocessing.forkserver as forkserver

    server = forkserver._forkserver  # noqa: SLF001 - the module's one server, to stop
    if not forks_workers():
        yield False
        return
    preload = list(getattr(server, "_preload_modules", ["__main__"]))
    forkserver.set_forkserver_preload(list(modules))
    server_environment = {**worker_environment(threads), FILL_VARIABLE: ",".join(fill)}
    added = {name: value for name, value in server_environment.items()
             if name not in os.environ}  # the user's own values stand
    os.environ.update(added)
    try:
        server.ensure_running()
        started = True
    except OSError:  # no socket or process for it here: spawned workers, as elsewhere
        started = False
    finally:
        for name in added:
            del os.environ[name]
    if not started:
        forkserver.set_forkserver_preload(preload)
        yield False
        return
    try:
        yield True
    finally:
        server._stop()  # noqa: SLF001 - waits for the server, which reaped the workers
        forkserver.set_forkserver_preload(preload)  # as the process had it
