"""Tone-mapping operators and display encoding for previews."""

from __future__ import annotations

import numpy as np

from hdrio.registry import MethodRegistry
from hdrio.tonemap.reinhard2002 import (
    tonemap_Reinhard2002_global,
    tonemap_Reinhard2002_global_tutorial,
    tonemap_Reinhard2002_local,
    tonemap_Reinhard2002_local_tutorial,
)

TONEMAP_METHODS: MethodRegistry = MethodRegistry(
    "tone-mapping",
    {
        "reinhard-global": tonemap_Reinhard2002_global,
        "reinhard-local": tonemap_Reinhard2002_local,
        "reinhard-global-tutorial": tonemap_Reinhard2002_global_tutorial,
        "reinhard-local-tutorial": tonemap_Reinhard2002_local_tutorial,
    },
    aliases={"Reinhard2002": "reinhard-global", "Reinhard2002-local": "reinhard-local"},
)


def encode_sRGB(display_linear: np.ndarray) -> np.ndarray:
    """Encode display-linear [0, 1] values with the sRGB inverse EOTF (IEC 61966-2-1)."""
    from colour.models import eotf_inverse_sRGB

    return np.asarray(eotf_inverse_sRGB(np.clip(display_linear, 0.0, 1.0)), dtype=np.float32)


__all__ = ["TONEMAP_METHODS", "encode_sRGB", "tonemap_Reinhard2002_global",
           "tonemap_Reinhard2002_global_tutorial", "tonemap_Reinhard2002_local",
           "tonemap_Reinhard2002_local_tutorial"]
