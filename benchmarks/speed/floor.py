"""The memory-bandwidth floor: a plain copy of the same bytes, on every core."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np


def parallel_copy(source: np.ndarray, destination: np.ndarray,
                  threads: int | None = None) -> None:
    """Copy ``source`` into ``destination`` in ``threads`` slabs along the first axis
    that has enough rows (NumPy releases the GIL while copying, so the slabs run at once)."""
    threads = threads or os.cpu_count() or 1
    flat_source = source.reshape(-1)
    flat_destination = destination.reshape(-1)
    bounds = np.linspace(0, flat_source.size, threads + 1).astype(np.int64)
    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(lambda k: np.copyto(flat_destination[bounds[k]: bounds[k + 1]],
                                          flat_source[bounds[k]: bounds[k + 1]]),
                      range(threads)))
