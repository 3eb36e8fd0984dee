"""What C libraries print while they decode, kept off the user's terminal."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading
from collections.abc import Iterator

_QUIET_LOCK = threading.Lock()
_quiet: dict[str, dict] = {name: {"depth": 0, "saved": -1, "sink": None}
                           for name in ("stdout", "stderr")}


_POOLS_SIZED: list[int] = []


def size_thread_pools() -> None:
    """OpenImageIO's thread pool and its OpenEXR's (compression, decompression) sized to
    this process's budget (:func:`hdrio.parallel.threads`: a farm worker's share of the
    machine, else every CPU it may use); set again only when the budget changed."""
    from hdrio.parallel import threads

    count = threads()
    if _POOLS_SIZED[-1:] == [count]:
        return
    import OpenImageIO as oiio

    oiio.attribute("threads", count)
    oiio.attribute("exr_threads", count)
    _POOLS_SIZED.append(count)


@contextlib.contextmanager
def quiet_native_stderr() -> Iterator[None]:
    """Swallow what C libraries (libpng, libjpeg) print on fd 2 while decoding.

    OpenImageIO reports the same problem through ``geterror()``, which we turn into one
    clear line; the library's own chatter would only add noise to it. Brackets are read
    on two threads and fd 2 belongs to the process, so the first thread in redirects it
    and the last one out restores it.
    """
    with _quiet_native("stderr"):
        yield


@contextlib.contextmanager
def quiet_native_output() -> Iterator[None]:
    """Swallow what C libraries print on fd 1 and fd 2 (OpenEXR's Python binding warns on
    standard output when it cannot read a file's pixels), as
    :func:`quiet_native_stderr`."""
    with _quiet_native("stdout"), _quiet_native("stderr"):
        yield


@contextlib.contextmanager
def _quiet_native(name: str) -> Iterator[None]:
    """fd of ``sys.<name>`` sent to a temporary file while any thread is inside."""
    stream = getattr(sys, name)
    state = _quiet[name]
    try:
        fd = stream.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    with _QUIET_LOCK:
        if state["depth"] == 0:
            stream.flush()
            state["saved"] = os.dup(fd)
            state["sink"] = tempfile.TemporaryFile()
            os.dup2(state["sink"].fileno(), fd)
        state["depth"] += 1
    try:
        yield
    finally:
        with _QUIET_LOCK:
            state["depth"] -= 1
            if state["depth"] == 0:
                os.dup2(state["saved"], fd)
                os.close(state["saved"])
                state["sink"].close()
