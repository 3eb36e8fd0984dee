"""Output paths of both front ends: checked before any work, folders made when written."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from hdrio.errors import HdrioError

EXR_SUFFIXES = frozenset({".exr"})
PREVIEW_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff"})


def _nearest_existing(folder: Path) -> Path:
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


def check_output(path: Path, allowed: Iterable[str], inputs: Iterable[str | Path] = ()
                 ) -> None:
    """Refuse an output name a run could not write, before any work.

    The suffix must be one of ``allowed``; the name must not be a folder or an input; the
    folder need not exist (:func:`make_parent` makes it) but the nearest existing one
    above it must be a writable folder.
    """
    allowed = sorted(allowed)
    if path.suffix.lower() not in allowed:
        raise HdrioError(f"{path}: unsupported output type; use {', '.join(allowed)}")
    if path.is_dir():
        raise HdrioError(f"{path}: is a folder, not a file name")
    existing = _nearest_existing(path.parent.absolute())
    if not existing.is_dir():
        raise HdrioError(f"{path}: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise HdrioError(f"{path}: folder {existing} is not writable")
    resolved = path.resolve()
    if any(Path(i).resolve() == resolved for i in inputs):
        raise HdrioError(f"{path}: output would overwrite an input")


def make_parent(path: str | Path) -> Path:
    """Make ``path``'s folder (and those above it) if missing; returns ``path``."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise HdrioError(f"{path}: cannot make folder {path.parent} "
                         f"({error.strerror})") from None
    return path
