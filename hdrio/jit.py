"""The first run after install: saying that kernels compile, and compiling on two cores.

Kernels compile on first use and are cached on disk (``cache=True``); a later process
loads them in milliseconds. The first run of a job can spend most of its time compiling,
so the pipeline announces it: "compiling kernels (first run only)". numba compiles on one
thread, so a first ``hdrio merge`` or ``hdrio demo`` also starts processes
(:func:`compile_ahead`, running :mod:`hdrio.precompile`) that compile the kernels the
job needs later (the merge's, alignment's and deghosting's, the preview's tone mapping)
while this one reads the brackets and solves the response; it waits for them before
those stages and then loads those kernels from the cache.
"""

from __future__ import annotations

import importlib
import subprocess
import sys
from collections.abc import Callable

STAGES: dict[str, tuple[str, ...]] = {
    "merge": ("hdrio.merge.kernel:merge_rows_by_pairs",),
    "motion": ("hdrio.align.quick:_read", "hdrio.align.pyramid:_base_rows",
               "hdrio.align.deghost:_consistency"),
    "preview": ("hdrio.tonemap.reinhard2002_kernels:_global_blocks",),
}
"""The kernels whose cache stands for each stage's (they compile together)."""


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
    process of that stage); the progress log times each stage."""
    _wait_for(stage)
    if not is_stage_cached(stage):
        say(f"compiling kernels (first run only): {stage}; later runs load them from the "
            "cache")


_LATER_NICENESS = (0, 4, 8)
"""Niceness of the compile-ahead processes for motion, merge and preview (CFS gives a
process of niceness 4 about 40 % of a nice-0 one's share)."""

_pending: dict[str, subprocess.Popen] = {}
"""Processes of :func:`compile_ahead` by the stage they compile for."""


def compile_ahead(preview: str | None, merge: Callable[[], bool], motion: bool = False
                  ) -> None:
    """On a first run, start processes (:mod:`hdrio.precompile`) compiling kernels into
    the disk cache: the merge kernel of 8-bit RGB brackets when ``merge()`` (asked only
    when a kernel is not cached), and with ``motion`` alignment's still check and
    deghosting's test of such brackets, in a process of their own (the longest compile
    of a first run: 14 s of CPU); the ``preview`` operator's (a ``TONEMAP_METHODS`` name,
    or None). Nothing when they are cached already or this process may use one CPU only.
    :func:`announce` of a stage waits for its process first."""
    from hdrio.parallel import threads

    if threads() < 2:
        return
    uncached = [stage for stage in ("merge", "motion")
                if (motion or stage == "merge") and not is_stage_cached(stage)]
    if uncached and not merge():  # their kernels are compiled for 8-bit RGB brackets
        uncached = []
    # In the order the job needs them, each later one at a lower priority: on 2 cores
    # the first run is CPU-bound, and the stage the job waits for next should not share
    # its core with one it needs seconds later.
    jobs = {("motion",): ["motion"] if "motion" in uncached else [],
            ("merge",): ["merge"] if "merge" in uncached else [],
            ("preview",): (
                [f"preview={preview}"] if preview and not is_stage_cached("preview") else [])}
    for niceness, (stages, names) in zip(_LATER_NICENESS, jobs.items(), strict=True):
        if names:
            process = subprocess.Popen([sys.executable, "-m", "hdrio.precompile",
                                        f"nice={niceness}", *names],
                                       stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                       stderr=subprocess.DEVNULL)
            _pending.update(dict.fromkeys(stages, process))


def _wait_for(stage: str) -> None:
    """Wait until :func:`compile_ahead`'s process for ``stage`` is done (its kernels are
    then in the cache; if it failed, they simply compile here on first use)."""
    process = _pending.pop(stage, None)
    if process is not None:
        process.wait()


def is_stage_cached(stage: str) -> bool:
    """True when every kernel standing for ``stage`` (a key of :data:`STAGES`) is cached."""
    return all(is_cached(_dispatcher(name)) for name in STAGES[stage])
