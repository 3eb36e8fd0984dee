"""Exposure of each bracket image linked into the HDR Merge node (no ``bpy`` here).

hdrio's own rules decide (:func:`hdrio.read_brackets`): EXIF for the whole set when every
file has an exposure time (``t * ISO/100 / N^2`` when aperture or ISO vary), else the
file-name convention (``church_1_60.jpg`` is 1/60 s).

The node also keeps where each exposure came from, so that a solve never runs on the
placeholders a new node starts with (:func:`placeholder_brackets`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from hdrio.io.brackets import read_brackets

PLACEHOLDER = "placeholder"
"""Source of an exposure nobody set: the node's starting value."""
TYPED = "typed"
"""Source of an exposure typed in the node."""


def exposures_for_files(paths: Sequence[str | Path]) -> tuple[list[float], str]:
    """Exposure of each file in ``paths``, in the order given (seconds, or relative), and
    where hdrio found them (its ``exposure_sources``: ``"exif"``, ``"filename"``, ...).

    Raises :class:`hdrio.InputError` naming the file when the set has no exposures or the
    images differ in size (two frames may share an exposure: the merge checks that they
    are one picture, :func:`hdrio.merge.ladder.check_repeated_exposures`).
    """
    stack = read_brackets(paths)
    by_file = dict(zip(stack.files, stack.exposures.tolist()))
    return [float(by_file[str(Path(path))]) for path in paths], str(stack.exposure_sources[0])


def sorted_order(exposures: Sequence[float]) -> list[int]:
    """Input indices from the shortest exposure to the longest (ties keep input order).

    The merge drops a channel from every bracket at least as long as one where it saturated,
    so the node wires its inputs in this order.
    """
    return sorted(range(len(exposures)), key=lambda index: exposures[index])


def edited_sources(sources: Sequence[str], before: Sequence[float],
                   after: Sequence[float]) -> list[str]:
    """``sources`` with every bracket whose exposure changed from ``before`` to ``after``
    marked :data:`TYPED`."""
    return [TYPED if old != new else source
            for source, old, new in zip(sources, before, after)]


def placeholder_brackets(sources: Sequence[str]) -> list[int]:
    """Numbers (from 1) of the brackets whose exposure is still a placeholder."""
    return [number for number, source in enumerate(sources, start=1) if source == PLACEHOLDER]


def exposure_state(sources: Sequence[str]) -> str:
    """A short line for the node: where the exposures came from, or what to do."""
    missing = placeholder_brackets(sources)
    if missing:
        which = ", ".join(str(number) for number in missing)
        return f"Type exposure of bracket {which}"
    kinds = sorted(set(sources))
    return "Exposures: " + ", ".join(kinds)


def input_problems(sizes: Sequence[tuple[int, int] | None], linked: Sequence[bool]) -> str:
    """The first problem with the node's inputs, as one short line, or ``""``.

    ``sizes[i]`` is bracket ``i + 1``'s image size ``(width, height)``, ``(0, 0)`` for an
    image without pixels (its file missing), ``None`` when not known (no image: a render
    pass, say); ``linked[i]`` tells whether its input is linked at all. Nothing linked is
    no problem (a node just added).
    """
    if not any(linked):
        return ""
    for number, (size, is_linked) in enumerate(zip(sizes, linked), start=1):
        if not is_linked:
            return f"Bracket {number} is not linked"
        if size is not None and 0 in size:
            return f"Bracket {number}: image has no pixels"
    known = [(number, size) for number, size in enumerate(sizes, start=1) if size is not None]
    for number, size in known[1:]:
        if size != known[0][1]:
            first, (width, height) = known[0][0], known[0][1]
            return f"Bracket {number} is {size[0]}x{size[1]}, bracket {first} {width}x{height}"
    return ""
