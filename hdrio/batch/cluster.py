"""Run sets on a Dask cluster (``distributed``, the ``farm`` extra).

Each set is one task; the worker that runs it reads the frames from and writes the
outputs (atomically) to storage every worker and the client see under the same paths,
and records the set in the journal. Dask's scheduler re-runs the tasks of a worker that
is lost (killed, out of memory, its machine gone) on the others; a set whose work fails
is reported and the others go on.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from typing import Any

from hdrio.batch.pool import (
    WORKER_START,
    OnResult,
    SetResult,
    Work,
    fork_server,
    run_set,
    work_module,
    worker_threads,
)
from hdrio.batch.tasks import SetTask

LOCAL = "local"
_PRE_SPAWN = "distributed.nanny.pre-spawn-environ"
_TRIM = "MALLOC_TRIM_THRESHOLD_"


def _distributed():
    try:
        import distributed
    except ImportError:
        raise ImportError("Dask is not installed: pip install 'hdrio[farm]'") from None
    return distributed


def parse_address(text: str) -> tuple[str, int | None]:
    """``local`` or ``local:N`` -> ``("local", N or None)``; else ``(address, None)``."""
    if text == LOCAL or text.startswith(LOCAL + ":"):
        count = text[len(LOCAL) + 1:]
        if count and (not count.isdigit() or int(count) < 1):
            raise ValueError(f"expected local or local:N with N >= 1 workers, got {text!r}")
        return LOCAL, int(count) if count else None
    if "://" not in text and ":" not in text:
        raise ValueError(f"expected a scheduler address (tcp://host:8786), local or "
                         f"local:N, got {text!r}")
    return text, None


def local_cluster(workers: int | None = None) -> Any:
    """A ``LocalCluster`` of ``workers`` processes (default: one per CPU), one thread
    each, kernel threads shared out between them; its dashboard on a free port.

    Its workers keep glibc's own ``malloc`` tuning: distributed sets
    ``MALLOC_TRIM_THRESHOLD_=65536`` in a worker's environment before it starts, and
    setting it turns off glibc's adaptive mmap threshold, so every buffer over 128 KB
    is mapped afresh and page-faulted in each time. On a 7 x 12 MP set that is ten times
    the page faults and 1.4x the CPU of the same set in a pool worker (``python -m
    benchmarks.farm``). A value the user exported is still passed on.
    """
    import dask

    from hdrio.parallel import threads, worker_environment

    distributed = _distributed()
    workers = workers or threads()
    with dask.config.set({f"{_PRE_SPAWN}.{_TRIM}": None}):
        return distributed.LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True,
            dashboard_address=":0", env=worker_environment(worker_threads(workers)))


@contextlib.contextmanager
def forked_workers(workers: int | None = None, work: Work | None = None,
                   fill: Sequence[str] = ()) -> Iterator[None]:
    """Inside, the workers of a :func:`local_cluster` of ``workers`` are forked from a
    fork server that has imported ``distributed``, what a set needs and the module of
    ``work`` (:func:`hdrio.batch.pool.fork_server`): a worker then starts without
    importing them itself (and ``fill``: :func:`hdrio.batch.pool.run_local`). A worker
    the nanny restarts is forked too. Leave it after the cluster is closed. Elsewhere
    than Linux, spawned workers as before."""
    import dask

    from hdrio.parallel import threads

    _distributed()
    share = worker_threads(workers or threads())
    modules = ["distributed", WORKER_START] + ([work_module(work)] if work else [])
    with fork_server(share, *modules, fill=fill) as forked, dask.config.set(
            {"distributed.worker.multiprocessing-method": "forkserver"} if forked else {}):
        yield


def run_dask(tasks: Sequence[SetTask], work: Work, client: Any,
             on_result: OnResult | None = None) -> list[SetResult]:
    """Run ``tasks`` on the Dask cluster of ``client`` (a ``distributed.Client``).

    ``on_result(result, done, total)`` is called here as each set finishes; a set that
    could not run at all (its task killed a worker too often) is a failed result.
    """
    distributed = _distributed()
    futures = {client.submit(run_set, work, task, key=f"hdrio-set-{task.index}-"
                             f"{task.fingerprint[:16]}", pure=False): task
               for task in tasks}
    results = []
    for future in distributed.as_completed(futures):
        task = futures[future]
        try:
            result = future.result()
        except Exception as error:  # KilledWorker, a lost scheduler, ...
            result = SetResult(task.index, False, f"error: {type(error).__name__}: {error}\n",
                               "", 0, 0.0, float("nan"))
        results.append(result)
        if on_result is not None:
            on_result(result, len(results), len(tasks))
    return results
