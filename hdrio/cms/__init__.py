"""Colour management: OpenColorIO spaces and conversions, input encodings, white balance,
calibration, display previews, checks (luminance itself is :mod:`hdrio.radiometry.luminance`).

The array-in, array-out API for front ends (``hdrio merge``, an oiiotool-style chain,
the Blender add-on) is :mod:`hdrio.cms.spaces`; see docs/colour.md.
"""

from hdrio.cms.spaces import (
    canonical_space,
    chromaticities,
    convert,
    display_view,
    interop_id,
    linear_space_names,
    load_config,
    require_scene_linear,
)

__all__ = ["canonical_space", "chromaticities", "convert", "display_view", "interop_id",
           "linear_space_names", "load_config", "require_scene_linear"]
