"""Colour management: luminance, OpenColorIO spaces and conversions, calibration, checks.

The array-in, array-out API for front ends (``hdrio merge``, an oiiotool-style chain,
the Blender add-on) is :mod:`hdrio.cms.spaces`; see docs/colour.md.
"""

from hdrio.cms.luminance import luminance, luminance_weights, rgb_chromaticities
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
           "linear_space_names", "load_config", "luminance", "luminance_weights",
           "require_scene_linear", "rgb_chromaticities"]
