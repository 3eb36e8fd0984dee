"""Output paths of both front ends: checked before any work (:mod:`hdrio.io.paths`, the
one place that checks paths), folders made when written."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from hdrio.io.paths import check_output as check_path
from hdrio.io.paths import make_folder_for

EXR_SUFFIXES = frozenset({".exr"})
PREVIEW_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff"})


def check_output(path: Path, allowed: Iterable[str], inputs: Iterable[str | Path] = ()
                 ) -> None:
    """Refuse an output name a run could not write, before any work.

    The suffix must be one of ``allowed``; the name must not be a folder or an input; the
    folder need not exist (:func:`make_parent` makes it) but the nearest existing one
    above it must be a writable folder.
    """
    check_path(path, inputs, allowed)


make_parent = make_folder_for
"""Make ``path``'s folder (and those above it) if missing; returns ``path``."""


def lossy_note(compression: str, pixel_type: str, path: Path) -> str | None:
    """The check report's note on an EXR ``path`` written with a lossy ``compression``
    (:func:`hdrio.io.write.lossy_compression`): the report counts the pixels as they were
    converted, before the codec; ``None`` for a lossless one."""
    from hdrio.io.write import lossy_compression

    if not lossy_compression(compression, pixel_type):
        return None
    return (f"counted before {compression}'s lossy compression; hdrio check {path.name} "
            "reads the pixels it kept")
