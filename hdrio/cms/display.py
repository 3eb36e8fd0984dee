"""Previews through an OpenColorIO display and view (e.g. ACES 2.0 SDR, sRGB Standard).

Beside the Reinhard operators: the config's own view transform renders the image, after
one exposure that puts the scene's log-average luminance (Reinhard's key, eq. 1) at
``key`` (0.18, mid grey), since relative radiance has an arbitrary scale.
"""

from __future__ import annotations

import numpy as np

from hdrio.cms.spaces import display_view
from hdrio.parallel import row_bands
from hdrio.radiometry.luminance import DEFAULT_SPACE, log_average_luminance, luminance

MID_GREY = 0.18


def preview_OCIO_display(rgb: np.ndarray, source: str, display: str, view: str, *,
                         colourspace: str = DEFAULT_SPACE, config: str | None = None,
                         key: float = MID_GREY) -> np.ndarray:
    """Display-encoded RGB in [0, 1] of scene-linear ``rgb`` (any scale).

    Parameters
    ----------
    rgb
        Scene-linear RGB ``(H, W, 3)``, relative or cd/m^2, in OCIO space ``source``.
    display, view
        An OCIO display and one of its views, e.g. ``"sRGB - Display"`` and
        ``"ACES 2.0 - SDR 100 nits (Rec.709)"`` in the built-in configs.
    colourspace
        colour-science name of ``rgb``'s primaries (for its luminance).
    """
    L = luminance(rgb, colourspace)
    exposure = key / log_average_luminance(L)
    encoded = display_view(np.asarray(rgb, dtype=np.float32) * np.float32(exposure), source,
                           display, view, config)
    bands = row_bands(encoded)
    for top in bands:  # in place, no full-size temporary (hdrio.parallel.ROWS_OF_VALUES)
        rows = encoded[top:top + bands.step]
        np.nan_to_num(rows, copy=False, nan=0.0)
        np.clip(rows, 0.0, 1.0, out=rows)
    return encoded
