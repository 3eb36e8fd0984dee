"""Reading ``--mask`` files: which pixels of which bracket the merge must not use.

A mask is an 8- or 16-bit image the size of the brackets (both turned upright by their
EXIF orientation, :mod:`hdrio.io.orientation`); a pixel is *excluded* where
its first channel is below half the code range (black), kept where it is white. The
``--mask`` values map to brackets so:

* one file: shared by every bracket;
* as many files as brackets: one per bracket, in the brackets' order;
* a name with ``{stem}`` (or ``{name}``): filled per bracket with that bracket's file
  stem (name), e.g. ``--mask masks/{stem}.png``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from hdrio.errors import HdrioError
from hdrio.io.brackets import read_codes
from hdrio.io.paths import check_input, fill_pattern, is_pattern


def mask_files(masks: Sequence[str], files: Sequence[str | Path]) -> list[Path]:
    """The mask file of each bracket in ``files`` (see the module's rules)."""
    if len(masks) == 1 and is_pattern(masks[0]):
        paths = []
        for name in files:
            try:
                paths.append(fill_pattern(masks[0], {"stem": Path(name).stem,
                                                     "name": Path(name).name}))
            except HdrioError as error:
                message = str(error).replace("output name", "mask name")
                raise HdrioError(f"--mask {masks[0]}: {message}") from None
        return paths
    if len(masks) == 1:
        return [Path(masks[0])] * len(files)
    if len(masks) != len(files):
        raise HdrioError(f"--mask given {len(masks)} times for {len(files)} brackets: give "
                         "one shared mask, one per bracket, or a pattern with {stem}")
    return [Path(mask) for mask in masks]


def read_masks(masks: Sequence[str], files: Sequence[str | Path],
               shape: tuple[int, int]) -> np.ndarray | None:
    """``(P, H, W)`` bool, true where bracket ``j`` (of ``files``) is excluded; ``None``
    when no mask is given. Raises :class:`~hdrio.errors.HdrioError` naming the mask file
    when it is unreadable or not ``shape`` ``(H, W)``."""
    if not masks:
        return None
    paths = mask_files(masks, files)
    read: dict[Path, np.ndarray] = {}
    for path in dict.fromkeys(paths):
        check_input(path, "a mask image")
        try:
            codes, code_max, _ = read_codes(path)
        except (HdrioError, ValueError, OSError) as error:
            raise HdrioError(f"--mask {path}: {error}") from None
        if codes.shape[:2] != tuple(shape):
            raise HdrioError(f"--mask {path}: {codes.shape[1]}x{codes.shape[0]} pixels, the "
                             f"brackets are {shape[1]}x{shape[0]}")
        read[path] = codes[..., 0] < (code_max + 1) // 2
    return np.stack([read[path] for path in paths])
