"""Input encodings of brackets: which RGB primaries the linearised code values have.

The recovered camera response linearises code values (no fixed transfer function is
assumed); the primaries and white of the result are those of the encoding the camera
wrote: sRGB (Rec.709 primaries, D65), Adobe RGB (1998), Display P3 or Rec.2020. The
encoding is taken from the file where it says (the ICC profile's description, else the
EXIF ``ColorSpace`` tag, 1 = sRGB), else from the caller's choice, else sRGB. A profile
of another wide-gamut encoding (ProPhoto RGB, as Lightroom exports 16-bit TIFFs; Wide
Gamut RGB; ECI RGB) is refused unless the caller chose one: merged as sRGB, its colours
would be far too dull without a word. A profile that names no encoding (canal's
``Camera RGB Profile``) says nothing.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from hdrio.errors import InputError
from hdrio.radiometry.luminance import rgb_colourspace


@dataclass(frozen=True)
class Encoding:
    """An input encoding: its colour-science colourspace and OCIO interop ID when linear."""

    name: str
    colour_science: str
    linear_interop_id: str


ENCODINGS: dict[str, Encoding] = {
    "sRGB": Encoding("sRGB", "ITU-R BT.709", "lin_rec709_scene"),
    "Adobe RGB (1998)": Encoding("Adobe RGB (1998)", "Adobe RGB (1998)", "lin_adobergb_scene"),
    "Display P3": Encoding("Display P3", "Display P3", "lin_p3d65_scene"),
    "Rec.2020": Encoding("Rec.2020", "ITU-R BT.2020", "lin_rec2020_scene"),
}
DEFAULT_ENCODING = "sRGB"

# Lower-case fragments of ICC profile descriptions, most specific first.
_ICC_MARKERS = (("adobe rgb", "Adobe RGB (1998)"), ("adobergb", "Adobe RGB (1998)"),
                ("display p3", "Display P3"), ("p3", "Display P3"), ("2020", "Rec.2020"),
                ("srgb", "sRGB"), ("iec61966-2", "sRGB"))
_ALIASES = {"srgb": "sRGB", "rec709": "sRGB", "adobergb": "Adobe RGB (1998)",
            "adobergb1998": "Adobe RGB (1998)", "adobe": "Adobe RGB (1998)",
            "displayp3": "Display P3", "p3": "Display P3", "p3d65": "Display P3",
            "rec2020": "Rec.2020", "bt2020": "Rec.2020", "2020": "Rec.2020"}
_OTHER_MARKERS = ("prophoto", "romm", "wide gamut", "widegamut", "ecirgb", "eci-rgb",
                  "colormatch")
"""Lower-case fragments of ICC profile descriptions of wide-gamut encodings not read."""
UNKNOWN = ""
"""The encoding :func:`encoding_from_metadata` names for such a profile."""


def encoding(name: str) -> Encoding:
    """The encoding called ``name`` (case, spaces, ``-``, ``(1998)`` ignored)."""
    key = "".join(ch for ch in name.lower() if ch.isalnum())
    canonical = _ALIASES.get(key) or _ALIASES.get(key.replace("1998", ""))
    if canonical is None:
        raise KeyError(f"unknown input encoding {name!r}; choose from {', '.join(ENCODINGS)}")
    return ENCODINGS[canonical]


def encoding_from_metadata(metadata: Mapping[str, object]) -> tuple[str, str] | None:
    """``(encoding name, evidence)`` from one file's metadata, or ``None`` if it is silent;
    the name is :data:`UNKNOWN` for an ICC profile of a wide-gamut encoding not in
    :data:`ENCODINGS` (:data:`_OTHER_MARKERS`).

    ``metadata`` holds ``ICCDescription`` and ``ExifColorSpace`` as read by
    :func:`hdrio.io.brackets.read_codes`.
    """
    description = str(metadata.get("ICCDescription") or "").strip()
    lowered = description.lower()
    for marker, name in _ICC_MARKERS:
        if marker in lowered:
            return name, f"ICC profile {description!r}"
    if any(marker in lowered for marker in _OTHER_MARKERS):
        return UNKNOWN, f"ICC profile {description!r}"
    if metadata.get("ExifColorSpace") == 1:
        return "sRGB", "EXIF ColorSpace 1"
    return None


def resolve_encoding(files: Sequence[str], metadata: Sequence[Mapping[str, object]],
                     fallback: str | None = None) -> tuple[Encoding, str]:
    """The stack's encoding and where it came from: file metadata, else ``fallback``.

    Raises :class:`InputError` naming the file when brackets declare different encodings,
    or when one's ICC profile names an encoding hdrio does not know and no ``fallback``
    says what its pixels are (with one, such a file counts as silent).
    """
    found = [(name, encoding_from_metadata(entry)) for name, entry in zip(files, metadata)]
    for name, hit in found:
        if hit is not None and hit[0] == UNKNOWN and not fallback:
            raise InputError(name, f"its {hit[1]} is not an encoding hdrio reads "
                                   f"({', '.join(ENCODINGS)}): export the brackets in one "
                                   "of them, or give --input-encoding NAME if their pixels "
                                   "are in it")
    declared = [(name, hit) for name, hit in found
                if hit is not None and hit[0] != UNKNOWN]
    if declared:
        first_file, (first, evidence) = declared[0]
        for name, (other, _) in declared[1:]:
            if other != first:
                raise InputError(name, f"is {other} but {first_file} is {first}: brackets "
                                       "must share one encoding")
        return ENCODINGS[first], evidence
    if fallback:
        return encoding(fallback), "option"
    return ENCODINGS[DEFAULT_ENCODING], "default"


def xyz_to_working(xyz: np.ndarray, space: str) -> np.ndarray:
    """Convert linear CIE XYZ (D65) to the linear RGB working ``space``, float32.

    Uses colour-science's matrix for the space, with a CAT02 adaptation when its white
    is not D65. Out-of-gamut colours come out negative, as they should in scene-linear.
    """
    import colour

    d65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    rgb = colour.XYZ_to_RGB(np.asarray(xyz, dtype=np.float64), rgb_colourspace(space), d65,
                            chromatic_adaptation_transform="CAT02")
    return np.asarray(rgb, dtype=np.float32)
