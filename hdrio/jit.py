"""Whether numba still has to compile a kernel (first run after install), to say so.

Kernels compile on first use and are cached on disk (``cache=True``); a later process
loads them in milliseconds. The first run of a job can spend most of its time compiling,
so the pipeline announces it: "compiling kernels (first run only)".
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

STAGES: dict[str, tuple[str, ...]] = {
    "response": ("hdrio.response.kernels:reduced_normal_matrix",),
    "merge": ("hdrio.merge.kernel:merge_kernel",),
    "preview": ("hdrio.tonemap.reinhard2002_kernels:_global_blocks",),
}
"""The kernel whose cache stands for each stage's (they compile together)."""


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
    :data:`STAGES`) are not in the cache yet; the progress log times each stage."""
    if not all(is_cached(_dispatcher(name)) for name in STAGES[stage]):
        say(f"compiling kernels (first run only): {stage}; later runs load them from the "
            "cache")
