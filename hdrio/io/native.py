"""What C libraries print while OpenImageIO decodes, kept off the user's terminal."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading
from collections.abc import Iterator

_QUIET_LOCK = threading.Lock()
_quiet = {"depth": 0, "saved": -1, "sink": None}


@contextlib.contextmanager
def quiet_native_stderr() -> Iterator[None]:
    """Swallow what C libraries (libpng, libjpeg) print on fd 2 while decoding.

    OpenImageIO reports the same problem through ``geterror()``, which we turn into one
    clear line; the library's own chatter would only add noise to it. Brackets are read
    on two threads and fd 2 belongs to the process, so the first thread in redirects it
    and the last one out restores it.
    """
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    with _QUIET_LOCK:
        if _quiet["depth"] == 0:
            sys.stderr.flush()
            _quiet["saved"] = os.dup(fd)
            _quiet["sink"] = tempfile.TemporaryFile()
            os.dup2(_quiet["sink"].fileno(), fd)
        _quiet["depth"] += 1
    try:
        yield
    finally:
        with _QUIET_LOCK:
            _quiet["depth"] -= 1
            if _quiet["depth"] == 0:
                os.dup2(_quiet["saved"], fd)
                os.close(_quiet["saved"])
                _quiet["sink"].close()
