"""Colour management: luminance and colour-space facts through colour-science."""

from hdrio.cms.luminance import luminance, luminance_weights, rgb_chromaticities

__all__ = ["luminance", "luminance_weights", "rgb_chromaticities"]
