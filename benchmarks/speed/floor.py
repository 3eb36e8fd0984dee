"""The memory-bandwidth floor: a plain copy of the same bytes, on every core."""

from __future__ import annotations

import numpy as np

from hdrio.parallel import on_threads

COPY_BLOCK = 1 << 22
"""Bytes per task (4 MB), as the merge's own blocks."""


def parallel_copy(source: np.ndarray, destination: np.ndarray) -> None:
    """Copy ``source`` into ``destination`` in blocks spread over hdrio's threads
    (:func:`hdrio.parallel.on_threads`; NumPy releases the GIL while copying)."""
    flat_source = source.reshape(-1)
    flat_destination = destination.reshape(-1)
    step = max(1, COPY_BLOCK // flat_source.itemsize)

    def blocks(first: int, last: int) -> None:
        np.copyto(flat_destination[first * step: last * step],
                  flat_source[first * step: last * step])

    on_threads(blocks, -(-flat_source.size // step))
