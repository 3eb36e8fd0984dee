"""The colour stage of a merge: encoding, white balance, absolute luminance, output space.

:func:`colour_stage` runs after the merge on radiance in the input encoding's linear
primaries; :func:`output_radiance` converts it to the EXR's working space (OpenColorIO);
:func:`colour_attributes` is the header that says what the numbers mean. The pipeline
calls these three; nothing here reads or writes files.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from hdrio.cms import spaces
from hdrio.cms.calibration import Calibration, Region, absolute_scale
from hdrio.cms.encoding import Encoding, resolve_encoding
from hdrio.cms.whitebalance import apply_gains, neutral_gains
from hdrio.errors import HdrioError
from hdrio.io.write import Float2
from hdrio.radiometry.curve import CameraResponse
from hdrio.stack import ExposureStack


@dataclass(frozen=True)
class ColourState:
    """What the colour stage found and did; everything here goes into the EXR header.

    Attributes
    ----------
    encoding, encoding_source
        The brackets' encoding (primaries of the linearised codes) and the evidence.
    luminance_scale
        cd/m^2 per unit of relative radiance, or ``None`` when the result is relative.
    calibration
        How ``luminance_scale`` was found.
    gains
        White balance gains applied per channel (``None``: the camera's balance kept).
    white_balance
        The neutral region ``x, y, w, h`` the gains came from.
    """

    encoding: Encoding
    encoding_source: str
    luminance_scale: float | None = None
    calibration: Calibration | None = None
    gains: tuple[float, ...] | None = None
    white_balance: Region | None = None


def colour_stage(stack: ExposureStack, response: CameraResponse, radiance: np.ndarray, *,
                 input_encoding: str | None = None, white_balance: Region | None = None,
                 calibration: Calibration | None = None) -> tuple[np.ndarray, ColourState]:
    """White balance then calibrate ``radiance``; returns the new radiance and the state.

    ``radiance`` (relative, input encoding's linear primaries) is not modified.
    """
    metadata: Sequence[Mapping[str, object]] = stack.metadata or [{}] * stack.count
    encoding, evidence = resolve_encoding(stack.files, metadata, input_encoding)
    space = encoding.colour_science
    gains = None
    if white_balance is not None and radiance.shape[-1] == 3:
        gains = neutral_gains(radiance, white_balance, space)
        radiance = apply_gains(radiance, gains)
    scale = None
    if calibration is not None:
        scale = absolute_scale(stack, response, radiance, calibration, space)
        radiance = np.asarray(radiance, dtype=np.float32) * np.float32(scale)
    state = ColourState(encoding, evidence, scale, calibration,
                        None if gains is None else tuple(float(g) for g in gains),
                        white_balance)
    return radiance, state


def output_radiance(radiance: np.ndarray, state: ColourState, output_space: str,
                    config: str | None = None) -> np.ndarray:
    """``radiance`` converted from the input encoding's linear space to ``output_space``.

    Returned as is (no copy: 288 MB at 24 MP) when the two spaces are the same.
    """
    source = state.encoding.linear_interop_id
    if radiance.shape[-1] != 3 or (spaces.canonical_space(source, config)
                                   == spaces.canonical_space(output_space, config)):
        return radiance
    return spaces.convert(radiance, source, output_space, config)


def colour_attributes(state: ColourState, output_space: str, config: str | None = None,
                      exposure_scale: float = 1.0) -> dict[str, object]:
    """EXR attributes: standard ones (``chromaticities``, ``colorInteropID``,
    ``whiteLuminance``, ``adoptedNeutral``) and ``hdrio:`` provenance (docs/metadata.md).

    ``exposure_scale`` is the factor applied to pixels before writing (half range).
    """
    attributes: dict[str, object] = {
        **space_attributes(output_space, config),
        "hdrio:inputEncoding": f"{state.encoding.name} ({state.encoding_source})",
        "hdrio:whiteBalance": "camera",
    }
    if state.gains is not None and state.white_balance is not None:
        region = ",".join(str(v) for v in state.white_balance)
        gains = " ".join(f"{g:.6g}" for g in state.gains)
        attributes["hdrio:whiteBalance"] = f"region {region}, gains {gains}"
    if state.luminance_scale is not None and state.calibration is not None:
        attributes["hdrio:units"] = "cd/m^2"
        # OpenEXR: luminance in cd/m^2 of RGB (1, 1, 1) as stored.
        attributes["whiteLuminance"] = 1.0 / float(exposure_scale)
        attributes["hdrio:luminanceScale"] = float(state.luminance_scale)
        attributes["hdrio:calibration"] = state.calibration.describe()
    return attributes


def space_attributes(space: str, config: str | None = None) -> dict[str, object]:
    """What says the pixels are scene-linear ``space``: ``chromaticities``,
    ``adoptedNeutral``, ``colorInteropID`` (when the space has one), ``hdrio:colorSpace``
    and ``hdrio:ocioConfig``.

    The one ``adoptedNeutral`` rule: the white of the space's own chromaticities (the
    ACES white for ACEScg and ACES2065-1, D65 for Rec.709), wherever the file is written.
    """
    chromaticities = spaces.chromaticities(space, config)
    attributes: dict[str, object] = {
        "chromaticities": chromaticities,
        "adoptedNeutral": Float2(chromaticities[6], chromaticities[7]),
        "hdrio:colorSpace": spaces.canonical_space(space, config),
        "hdrio:ocioConfig": spaces.config_label(config),
    }
    interop = spaces.interop_id(space, config)
    if interop:
        attributes["colorInteropID"] = interop
    return attributes


# Attributes that describe scene-linear radiance, untrue of a tone-mapped image.
_SCENE_LINEAR_ONLY = ("whiteLuminance", "hdrio:exposureScale", "hdrio:luminanceScale",
                      "hdrio:calibration", "colorInteropID", "adoptedNeutral")


def display_attributes(attributes: Mapping[str, object], rendering: str,
                       display: str | None = None, config: str | None = None
                       ) -> dict[str, object]:
    """``attributes`` of a scene-linear image, relabelled for its display rendering.

    ``hdrio:units`` becomes ``display-referred``, ``hdrio:colorSpace`` the display
    (sRGB for the Reinhard operators), ``hdrio:rendering`` says how (``rendering``);
    ``chromaticities`` become the display's primaries (Rec.709 / D65 when unknown) and
    what only holds for radiance (exposure scale, absolute luminance) is dropped.
    Provenance (sources, response, settings) is kept.
    """
    from hdrio.cms.checks import REC709_D65

    relabelled = {name: value for name, value in attributes.items()
                  if name not in _SCENE_LINEAR_ONLY}
    chromaticities: tuple[float, ...] = REC709_D65
    name = "sRGB - Display"
    if display is not None:
        name = display
        try:
            chromaticities = spaces.chromaticities(display, config)
        except (HdrioError, KeyError):  # no matrix to the reference: Rec.709
            chromaticities = REC709_D65
    relabelled.update({"hdrio:units": "display-referred", "hdrio:colorSpace": name,
                       "hdrio:rendering": rendering, "chromaticities": chromaticities})
    return relabelled
