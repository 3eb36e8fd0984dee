"""Where decoded brackets live: in memory, or staged in a temporary file beyond a budget.

A stack's code values grow with the bracket count (72 MB per 24 MP 8-bit bracket). Up to
the budget they are an ordinary array. Beyond it they are decoded into a memory-mapped
temporary file (unlinked at once, so nothing is left behind whatever happens), and each
bracket's pages are handed back to the kernel as soon as it is decoded, and each band of
rows as soon as it is merged (``madvise(MADV_DONTNEED)``: the data stay in the file and
the page cache, but no longer count against the process). The process's peak memory then
no longer depends on the number of brackets: ``benchmarks/speed`` measures 5, 7 and 9.

Budget: ``HDRIO_MEMORY_BUDGET_MB`` (default 256 MB, three 24 MP brackets); the file goes
to ``HDRIO_TMPDIR``, else the system's temporary folder.
"""

from __future__ import annotations

import math
import mmap
import os
import tempfile
import weakref

import numpy as np

DEFAULT_BUDGET_MB = 256

_WRITE_BYTES = 2**16
"""Bytes a staged write hands the file at once. The page cache holds what one write
brings in a folio of up to that size, and a read through the mapping maps a whole folio:
written in 2.6 MB bands, the deghosting test's sparse reads mapped all 504 MB of a
7 x 24 MP stack at once (its band-by-band release notwithstanding)."""

CANDIDATE_LIMIT = 2**14
"""Pixels of the regular grid the response's sampler and the noise fit read (at most)."""


def budget_bytes() -> int:
    """Bytes of code values kept in ordinary memory before staging to a file."""
    from hdrio.numbers import check_number

    configured = os.environ.get("HDRIO_MEMORY_BUDGET_MB", "").strip()
    megabytes = (check_number("HDRIO_MEMORY_BUDGET_MB", configured, minimum=0.0,
                              hint="megabytes of decoded brackets kept in memory")
                 if configured else DEFAULT_BUDGET_MB)
    return int(megabytes * 2**20)


def codes_buffer(shape: tuple[int, ...], dtype, budget: int | None = None) -> np.ndarray:
    """An uninitialised ``shape`` array: in memory within ``budget`` bytes, else staged."""
    dtype = np.dtype(dtype)
    size = int(np.prod(shape)) * dtype.itemsize
    if size <= (budget_bytes() if budget is None else budget):
        return np.empty(shape, dtype=dtype)
    folder = os.environ.get("HDRIO_TMPDIR") or None
    with tempfile.TemporaryFile(prefix="hdrio-codes-", dir=folder) as backing:
        backing.truncate(size)
        # The mapping keeps the (already unlinked) file alive after it is closed here.
        staged = np.memmap(backing, dtype=dtype, mode="r+", shape=shape)
        if hasattr(mmap, "MADV_RANDOM"):  # a sparse read maps its pages, not their folios
            staged._mmap.madvise(mmap.MADV_RANDOM)
        # A descriptor of its own for write_rows, closed with the array.
        staged.hdrio_descriptor = os.dup(backing.fileno())
        weakref.finalize(staged, os.close, staged.hdrio_descriptor)
        return staged


def is_staged(codes: np.ndarray) -> bool:
    return isinstance(codes, np.memmap) and getattr(codes, "_mmap", None) is not None


def release(codes: np.ndarray, bracket: int | None = None, top: int = 0,
            bottom: int | None = None) -> None:
    """Give back the pages of rows ``top .. bottom`` of ``bracket`` (every bracket when
    ``None``) of a staged ``(P, H, ...)`` array; nothing for an in-memory one.

    Only whole pages inside the range are released (a page shared with the next rows
    stays), so a band's neighbours are never touched.
    """
    if not is_staged(codes):
        return
    row_bytes = int(np.prod(codes.shape[2:])) * codes.itemsize
    height = codes.shape[1]
    bottom = height if bottom is None else bottom
    start_of = codes.ctypes.data - _mapping_address(codes)
    brackets = range(codes.shape[0]) if bracket is None else (bracket,)
    for j in brackets:
        first = start_of + (j * height + top) * row_bytes
        last = start_of + (j * height + bottom) * row_bytes
        first = -(-first // mmap.PAGESIZE) * mmap.PAGESIZE
        last = last // mmap.PAGESIZE * mmap.PAGESIZE
        if last > first:
            codes._mmap.madvise(mmap.MADV_DONTNEED, first, last - first)


def write_rows(codes: np.ndarray, top: int, rows: np.ndarray) -> bool:
    """Write ``rows`` (``(n, W, C)``, contiguous) over rows ``top .. top + n`` of one
    bracket ``codes`` ``(H, W, C)`` of a staged array through its file (``pwrite``), not
    its mapping; False (nothing written) for an in-memory array.

    Written through the mapping, every 4 KB page faulted on its own: the file's hole read
    and zeroed, the page made writable, its block reserved, then handed back. A 7 x 24
    MP JPEG stack decoded on 2 threads spent 0.6 s of system CPU that way, 0.2 s written
    through the file (the mapping sees the same page cache)."""
    root = _root(codes)
    descriptor = getattr(root, "hdrio_descriptor", None)
    if descriptor is None or not is_staged(codes) or not hasattr(os, "pwrite"):
        return False  # in memory (or no pwrite, as on Windows: written through the mapping)
    target = codes[top:top + rows.shape[0]]
    if not (target.flags.c_contiguous and rows.flags.c_contiguous
            and rows.dtype == codes.dtype and rows.shape == target.shape):
        raise ValueError(f"rows {rows.shape} {rows.dtype} do not fit {target.shape}")
    data = memoryview(rows).cast("B")
    position = target.ctypes.data - _mapping_address(codes)
    while data:  # in pieces, so that the page cache keeps small folios (see above)
        written = os.pwrite(descriptor, data[:_WRITE_BYTES], position)
        data, position = data[written:], position + written
    return True


def _root(codes: np.ndarray) -> np.ndarray:
    """The array ``codes`` is a view of (itself when it owns its memory)."""
    base = codes
    while isinstance(base.base, np.ndarray):
        base = base.base
    return base


def _mapping_address(codes: np.memmap) -> int:
    """Address of the first byte of the mapping ``codes`` is a view of."""
    base = _root(codes)
    return base.ctypes.data - int(getattr(base, "offset", 0))


def strided_copy(codes: np.ndarray, stride: int) -> np.ndarray:
    """``codes[:, ::stride, ::stride]`` as an ordinary array, one bracket at a time,
    releasing each staged bracket's pages after it: the page cache maps a file in large
    folios (up to 2 MB), so even every 39th row maps most of a bracket."""
    grid = np.empty((codes.shape[0], *codes[0, ::stride, ::stride].shape), codes.dtype)
    for j in range(codes.shape[0]):
        grid[j] = codes[j, ::stride, ::stride]
        release(codes, j)
    return grid


def gather_pixels(codes: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Code values ``(P, N, C)`` at flat pixel ``indices`` of ``(P, H, W, C)`` codes, one
    bracket at a time (releasing, as :func:`strided_copy`)."""
    count, height, width, channels = codes.shape
    out = np.empty((count, indices.size, channels), codes.dtype)
    for j in range(count):
        out[j] = codes[j].reshape(height * width, channels)[indices]
        release(codes, j)
    return out


def candidate_stride(height: int, width: int, limit: int = CANDIDATE_LIMIT) -> int:
    """The smallest grid stride that leaves at most ``limit`` pixels of ``height x width``."""
    stride = max(1, math.ceil(math.sqrt(height * width / limit)))
    while -(-height // stride) * -(-width // stride) > limit:
        stride += 1
    return stride
