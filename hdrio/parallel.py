"""How many threads hdrio's kernels use, ways to spread work over them, and helper
processes that end with their parent."""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")
R = TypeVar("R")
_DONE = object()  # read_ahead's end marker
_PR_SET_PDEATHSIG = 1
_M_ARENA_MAX = -8  # mallopt's parameter (malloc.h)
_PARENT_POLL_S = 0.5


def threads() -> int:
    """Threads the kernels use: ``HDRIO_THREADS`` if set, else the CPUs this process may
    run on."""
    configured = os.environ.get("HDRIO_THREADS", "").strip()
    if configured.isdigit() and int(configured) > 0:
        return int(configured)
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


BLAS_POOLS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""The BLAS libraries' thread pools, which hdrio's processes keep to one thread: hdrio's
kernels are its own (numba, on :func:`threads`), and its BLAS work is 3 x 3 colour
matrices, small normal equations and matrix-vector products whose threads would split
rows alone. A pool of one thread per CPU spins after it starts and after each call it
shares out: on the 16-core device a warm merge of 7 x 24 MP had spent 4.7-4.8 CPU
seconds when it began reading, against 1.27 on one CPU and 1.76 on four (docs/speed.md,
"Many cores"). NumPy's and SciPy's OpenBLAS each start such a pool when they load."""


def blas_on_one_thread() -> None:
    """Keep this process's BLAS pools (:data:`BLAS_POOLS`, read when NumPy and SciPy load,
    so before they are imported) to one thread, where the user has not sized them."""
    for name in BLAS_POOLS:
        os.environ.setdefault(name, "1")


def worker_environment(count: int) -> dict[str, str]:
    """The environment of a worker process given ``count`` of the machine's CPUs (a farm
    worker, a process of ``--group``'s pool, a Dask worker): hdrio's own kernels
    (``HDRIO_THREADS``), numba's parallel kernels and any OpenMP or BLAS pool a library
    starts are all sized to it, so that workers sharing a machine never run more threads
    than it has cores; BLAS on one thread (:data:`BLAS_POOLS`). OpenImageIO's and
    OpenEXR's pools follow ``HDRIO_THREADS`` (:func:`hdrio.io.native.size_thread_pools`).
    glibc's heap arenas are held to :data:`HEAP_ARENAS` (:func:`limit_heap_arenas`)."""
    value = str(max(1, int(count)))
    return {**{name: value for name in ("HDRIO_THREADS", "NUMBA_NUM_THREADS",
                                        "OMP_NUM_THREADS")},
            **{name: "1" for name in BLAS_POOLS}, "MALLOC_ARENA_MAX": str(HEAP_ARENAS)}


ROWS_OF_VALUES = 1 << 18
"""Values a band of rows holds when a whole image goes through NumPy steps band by band
(:func:`row_bands`: the preview's encoding and 8-bit codes, colour conversions, the
exclusions of ``--exclude-color`` and ``--mask``): each
step then makes a 1 MB temporary, which the heap hands out again, where a 24 MP image's
288 MB temporaries were each a fresh mapping, faulted in page by page (a 24 MP preview
took 3.0-4.4 s, 4.2-5.3 s of system CPU in the whole merge, and raised its peak from 0.56
to 2.0 GB; docs/speed.md)."""


def row_bands(values) -> range:
    """Where the bands of ``values``'s first axis start, each of about
    :data:`ROWS_OF_VALUES` values (at least one row); its ``step`` is a band's rows.
    ``range(0, 1)`` for a scalar."""
    if values.ndim == 0:
        return range(0, 1)
    step = max(1, ROWS_OF_VALUES // max(1, values[0].size))
    return range(0, values.shape[0], step)


def on_threads(kernel: Callable[..., None], tasks: int, *args: object) -> None:
    """``kernel(start, stop, *args)`` over tasks ``0 .. tasks - 1``, in chunks of
    consecutive tasks (eight per thread) that the threads take from a queue as they
    finish: on a machine shared with other work, a thread that gets less CPU simply takes
    fewer chunks (a fixed half each left the call waiting on the slower thread). The
    kernels must release the GIL (numba ``nogil``, NumPy ufuncs, copies)."""
    workers = max(1, min(threads(), tasks))
    if workers == 1:
        kernel(0, tasks, *args)
        return
    chunks = min(tasks, 8 * workers)
    bounds = [tasks * k // chunks for k in range(chunks + 1)]
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="hdrio") as pool:
        futures = [pool.submit(kernel, start, stop, *args)
                   for start, stop in zip(bounds[:-1], bounds[1:])]
        for future in futures:
            future.result()


def map_on_threads(function: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """``[function(item) for item in items]``, the items spread over the threads (each
    one task; for a few independent pieces of NumPy or LAPACK work, which release the
    GIL), in the items' order. One thread: a plain loop."""
    workers = max(1, min(threads(), len(items)))
    if workers == 1:
        return [function(item) for item in items]
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="hdrio") as pool:
        return list(pool.map(function, items))


def read_ahead(items: Iterator[T]) -> Iterator[T]:
    """``items``, with the next one produced on a second thread while the caller works
    on this one (a decoder that releases the GIL, such as OpenImageIO's, then overlaps
    with the caller's kernels). One item ahead at most: memory stays at two items."""
    if threads() == 1:
        yield from items
        return
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="hdrio-read") as pool:
        upcoming = pool.submit(next, items, _DONE)
        while (item := upcoming.result()) is not _DONE:
            upcoming = pool.submit(next, items, _DONE)
            yield item


HEAP_ARENAS = 4
"""glibc heap arenas a hdrio process may use (``MALLOC_ARENA_MAX``). glibc gives threads
up to eight arenas per core, and each keeps the pages its threads freed: on 16 threads a
``--group`` worker's peak crept from 687 MB after its first set of 7 x 12 MP to 800 MB
after its eighth (1.2-1.3 GB after 48 on the 16-core device), a 9 x 24 MP merge peaked
at 652 MB. With four arenas: 682 -> 727 MB, and 625 MB (this 2-core machine,
``HDRIO_THREADS=16``; wall and CPU time no worse in one run of each)."""


def limit_heap_arenas() -> bool:
    """Hold this process to :data:`HEAP_ARENAS` glibc heap arenas (``mallopt``), unless
    the user set ``MALLOC_ARENA_MAX`` (glibc then follows theirs). True when applied.
    Call it before the threads start (the command's entry, a pool worker's start); Dask's
    local workers get the variable in their environment (:func:`worker_environment`)."""
    if not sys.platform.startswith("linux") or os.environ.get("MALLOC_ARENA_MAX"):
        return False
    try:
        return bool(ctypes.CDLL(None).mallopt(_M_ARENA_MAX, HEAP_ARENAS))
    except (OSError, AttributeError):  # not glibc
        return False


def die_with_parent(parent_pid: int, forked: bool = False) -> None:
    """Make this process exit when ``parent_pid`` (its parent, or with ``forked`` the
    process whose fork server forked this one) does. On Linux the kernel also kills it
    when its actual parent dies (a fork server exits once its last client has)."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):
            pass

    def alive() -> bool:
        if not forked:
            return os.getppid() == parent_pid
        try:
            os.kill(parent_pid, 0)  # signal 0: is there such a process (of this user)
        except OSError:  # none, or another user's: the id was reused
            return False
        return True

    if not alive():  # the parent died before the line above
        os._exit(1)

    def watch() -> None:
        while alive():
            time.sleep(_PARENT_POLL_S)
        os._exit(1)

    threading.Thread(target=watch, name="hdrio-parent-watch", daemon=True).start()
