"""Exposure of each bracket image linked into the HDR Merge node (no ``bpy`` here).

hdrio's own rules decide (:func:`hdrio.read_brackets`): EXIF for the whole set when every
file has an exposure time (``t * ISO/100 / N^2`` when aperture or ISO vary), else the
file-name convention (``church_1_60.jpg`` is 1/60 s).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from hdrio.io.brackets import read_brackets


def exposures_for_files(paths: Sequence[str | Path]) -> list[float]:
    """Exposure of each file in ``paths``, in the order given (seconds, or relative).

    Raises :class:`hdrio.InputError` naming the file when the set has no exposures, the
    images differ in size, or two exposures coincide.
    """
    stack = read_brackets(paths)
    by_file = dict(zip(stack.files, stack.exposures.tolist()))
    return [float(by_file[str(Path(path))]) for path in paths]


def sorted_order(exposures: Sequence[float]) -> list[int]:
    """Input indices from the shortest exposure to the longest (ties keep input order).

    The merge drops a channel from every bracket at least as long as one where it saturated,
    so the node wires its inputs in this order.
    """
    return sorted(range(len(exposures)), key=lambda index: exposures[index])
