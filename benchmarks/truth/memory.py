"""Peak resident memory of a call, native allocations (OpenCV, BLAS) included.

A background thread samples ``VmRSS`` from ``/proc/self/status`` every few
milliseconds; the peak minus the value just before the call is reported. Where
``/proc`` is absent (not Linux) the peak is ``None``.

Before the baseline, glibc's ``malloc_trim(0)`` hands freed heap pages back to the
system: otherwise a repeated call reuses memory its previous run freed but the
allocator kept, and its peak reads near zero (OpenCV's did, before this).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import threading
import time
from pathlib import Path
from types import TracebackType

_STATUS = Path("/proc/self/status")


def _load_trim():
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return libc.malloc_trim
    except (OSError, AttributeError):  # not glibc
        return None


_MALLOC_TRIM = _load_trim()


def release_free_memory() -> None:
    """Return the allocator's free pages to the system (glibc only; else nothing)."""
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


def rss_bytes() -> int | None:
    """Current resident set size in bytes, or ``None`` without ``/proc``."""
    try:
        with _STATUS.open() as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


class PeakMemory:
    """Context manager: ``with PeakMemory() as m: ...`` then ``m.peak_mb``.

    Parameters
    ----------
    interval
        Seconds between samples (default 2 ms). Allocations that live shorter than
        this can be missed; a final sample is taken on exit.
    """

    def __init__(self, interval: float = 0.002) -> None:
        self.interval = interval
        self.baseline: int | None = None
        self.peak: int | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _sample(self) -> None:
        while not self._stop.is_set():
            value = rss_bytes()
            if value is not None and (self.peak is None or value > self.peak):
                self.peak = value
            self._stop.wait(self.interval)

    def __enter__(self) -> PeakMemory:
        release_free_memory()
        self.baseline = rss_bytes()
        self.peak = self.baseline
        if self.baseline is not None:
            self._thread = threading.Thread(target=self._sample, daemon=True)
            self._thread.start()
            time.sleep(0)  # let the sampler take its first reading
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        final = rss_bytes()
        if final is not None and self.peak is not None:
            self.peak = max(self.peak, final)

    @property
    def peak_mb(self) -> float | None:
        """Peak RSS during the block minus RSS before it, in MB (10^6 bytes)."""
        if self.baseline is None or self.peak is None:
            return None
        return max(0, self.peak - self.baseline) / 1e6
