"""Timing a call the same way everywhere: warm, repeated, median wall time, peak memory."""

from __future__ import annotations

import gc
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from benchmarks.truth.memory import PeakMemory


@dataclass
class Timing:
    """Wall times (s) of every repeat, their median, and the largest peak RSS (MB)."""

    times: list[float]
    peak_mb: float | None
    result: Any = None

    @property
    def seconds(self) -> float:
        return statistics.median(self.times)


def measure_call(function: Callable[[], Any], repeats: int = 3, warmup: int = 0) -> Timing:
    """Call ``function`` ``warmup`` times untimed, then ``repeats`` times, each under
    :class:`~benchmarks.truth.memory.PeakMemory`; keep the last result."""
    for _ in range(warmup):
        function()
    times: list[float] = []
    peaks: list[float] = []
    result = None
    for _ in range(max(1, repeats)):
        result = None
        gc.collect()
        with PeakMemory() as memory:
            start = time.perf_counter()
            result = function()
            times.append(time.perf_counter() - start)
        if memory.peak_mb is not None:
            peaks.append(memory.peak_mb)
    return Timing(times, max(peaks) if peaks else None, result)


def measure_alternately(calls: dict[str, Callable[[], Any]], repeats: int = 3,
                        warmup: int = 1) -> dict[str, Timing]:
    """Time several calls in turn, one of each per repeat (after ``warmup`` untimed
    rounds), so that a drift in the machine's speed falls on all of them alike. Each
    call is timed as :func:`measure_call` times it; its :class:`Timing` keeps every
    repeat's time, the largest peak and the last result."""
    for _ in range(warmup):
        for call in calls.values():
            call()
    timings = {name: Timing([], None) for name in calls}
    for _ in range(max(1, repeats)):
        for name, call in calls.items():
            timing = timings[name]
            timing.result = None  # free the previous result before the next call
            once = measure_call(call, 1)
            timing.times += once.times
            timing.result = once.result
            if once.peak_mb is not None:
                timing.peak_mb = max(timing.peak_mb or 0.0, once.peak_mb)
    return timings
