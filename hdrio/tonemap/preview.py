"""The preview: merged radiance tone-mapped by a named operator and encoded for an sRGB
display."""

from __future__ import annotations

import numpy as np

from hdrio.numbers import check_tonemap_parameters
from hdrio.parallel import row_bands
from hdrio.radiometry.luminance import DEFAULT_SPACE, DELTA, log_average_luminance, luminance
from hdrio.tonemap import TONEMAP_METHODS, encode_sRGB


def render_preview(radiance: np.ndarray, operator: str = "reinhard-global",
                   space: str = DEFAULT_SPACE, unseen: np.ndarray | None = None,
                   **parameters: float) -> np.ndarray:
    """Tone-map ``radiance`` and encode it for an sRGB display: values in [0, 1].

    ``parameters`` go to the operator (e.g. ``key=0.18`` for the Reinhard operators).
    Greyscale radiance (``(H, W, 1)``) is tone-mapped as grey RGB (its luminance is its
    one channel, since the weights sum to 1) and encoded as RGB. ``unseen`` ``(H, W)``
    pixels (masked everywhere) are shown black and leave the key as the rest gives it:
    they are filled, for the operator, with grey at the others' log-average luminance
    (which does not move eq. 1's mean).
    """
    function = TONEMAP_METHODS[operator]
    canonical = TONEMAP_METHODS.canonical(operator)
    check_tonemap_parameters(canonical, parameters)
    if radiance.shape[-1] == 1:
        radiance = np.repeat(radiance, 3, axis=-1)
    if unseen is not None:
        seen = luminance(radiance[~unseen], space)
        radiance = radiance.copy()
        radiance[unseen] = log_average_luminance(seen) - DELTA if seen.size else 0.0
    if canonical.endswith("tutorial"):
        display = function(radiance.astype(np.float64), **parameters)
    else:
        display = function(radiance, space=space, **parameters)
    # The operators return a new array: changed in place, band by band, with no
    # full-size temporary (hdrio.parallel.ROWS_OF_VALUES; nan_to_num's masks of a 24 MP
    # image held 360 MB).
    bands = row_bands(display)
    for top in bands:
        np.nan_to_num(display[top:top + bands.step], copy=False, nan=0.0)
    if display.shape[-1] == 1:
        display = np.repeat(display, 3, axis=-1)
    if unseen is not None:
        display[unseen] = 0.0
    return encode_sRGB(display, out=display if display.dtype == np.float32 else None)
