"""EXIF orientation: brackets are merged upright, as every photo viewer shows them.

A camera or phone held in portrait usually stores its pixels as the sensor read them
(landscape) and says in the EXIF ``Orientation`` tag (1-8, TIFF 6.0) how to turn them
for display. Merged as stored, a portrait bracket set became a sideways EXR and
preview. :mod:`hdrio.io.brackets` decodes each bracket straight into the upright
image: :func:`stored_view` is a view of the upright array with the stored shape, so the
decoder's bands land where they belong with no second copy. Camera RAW files are turned
upright by :mod:`hdrio.io.raw` (LibRaw's own flip).

What each value asks, as OpenImageIO's ``ImageBufAlgo.reorient`` does it (the tests
compare the two for every value): 1 as stored; 2 mirrored left to right; 3 turned 180
degrees; 4 mirrored top to bottom; 5 transposed; 6 turned 90 degrees clockwise; 7
transposed the other way (turned 180 degrees and transposed); 8 turned 90 degrees
counter-clockwise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

UPRIGHT = 1
"""The EXIF orientation of pixels stored as they are shown."""

DESCRIPTIONS = {1: "as stored", 2: "mirrored left to right", 3: "turned 180 degrees",
                4: "mirrored top to bottom", 5: "transposed",
                6: "turned 90 degrees clockwise", 7: "transposed and turned 180 degrees",
                8: "turned 90 degrees counter-clockwise"}
"""What turning a bracket upright did, per EXIF orientation (the summary's words)."""


TURNS = {1: (False, False, False), 2: (False, False, True), 3: (False, True, True),
         4: (False, True, False), 5: (True, False, False), 6: (True, False, True),
         7: (True, True, True), 8: (True, True, False)}
"""Each orientation as ``(transpose, flip rows, flip columns)``: the stored image
transposed first (when asked), then flipped, is the upright one."""


def orientation_of(value) -> int:
    """An EXIF ``Orientation`` as read (``None``, or out of range: as stored)."""
    try:
        orientation = int(value)
    except (TypeError, ValueError):
        return UPRIGHT
    return orientation if orientation in TURNS else UPRIGHT


def swaps_axes(orientation: int) -> bool:
    """Whether turning upright exchanges height and width (5-8)."""
    return TURNS[orientation][0]


def upright_size(height: int, width: int, orientation: int) -> tuple[int, int]:
    """``(height, width)`` of the upright image of a stored ``height x width`` one."""
    return (width, height) if swaps_axes(orientation) else (height, width)


def stored_view(upright: np.ndarray, orientation: int) -> np.ndarray:
    """A view of ``upright`` ``(H, W, ...)`` with the stored image's shape, such that
    writing the stored pixels into it leaves ``upright`` holding them turned upright
    (the inverse of :func:`upright_view`)."""
    swap, flip_rows, flip_columns = TURNS[orientation]
    view = upright[::-1] if flip_rows else upright
    view = view[:, ::-1] if flip_columns else view
    return view.swapaxes(0, 1) if swap else view


def upright_view(stored: np.ndarray, orientation: int) -> np.ndarray:
    """``stored`` ``(H, W, ...)`` as a view turned upright (:data:`TURNS`)."""
    swap, flip_rows, flip_columns = TURNS[orientation]
    view = stored.swapaxes(0, 1) if swap else stored
    view = view[::-1] if flip_rows else view
    return view[:, ::-1] if flip_columns else view


def place(band: np.ndarray, upright: np.ndarray, top: int, orientation: int) -> None:
    """Stored rows ``top ..`` (``band``, ``(rows, W, C)``) into their place in ``upright``
    ``(H, W, C)`` (both contiguous in ``C``). A turned band is first turned in a copy of
    its own, a pixel (all its channels) at a time, so that its rows go out in the order
    ``upright`` holds them: written straight through :func:`stored_view`, a channel at a
    time, each pixel of a turned band landed on another row (a 24 MP bracket 0.27 s, now
    0.11 s; stored upright, 0.004 s)."""
    if orientation == UPRIGHT:
        upright[top:top + band.shape[0]] = band
        return
    pixel = np.dtype((np.void, band.shape[-1] * band.itemsize))
    region = stored_view(upright.view(pixel)[..., 0], orientation)[top:top + band.shape[0]]
    upright_view(region, orientation)[...] = np.ascontiguousarray(
        upright_view(band.view(pixel)[..., 0], orientation))


def turned(metadata) -> list[int]:
    """Each bracket's EXIF orientation that reading turned upright (1: none), from the
    stack's ``metadata`` (:func:`hdrio.io.brackets.read_codes` records it there)."""
    return [orientation_of((entry or {}).get("Orientation")) for entry in metadata or ()]


def turned_text(files, metadata) -> str | None:
    """The summary's words for the brackets turned upright, grouped by what was done
    (``turned 90 degrees clockwise (orientation 6): a.jpg, b.jpg``), or None."""
    groups: dict[int, list[str]] = {}
    for name, orientation in zip(files, turned(metadata)):
        if orientation != UPRIGHT:
            groups.setdefault(orientation, []).append(Path(name).name)
    if not groups:
        return None
    return "; ".join(f"{DESCRIPTIONS[o]} (orientation {o}): {', '.join(names)}"
                     for o, names in sorted(groups.items()))
