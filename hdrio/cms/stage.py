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
from hdrio.io.write import Float2
from hdrio.response.curve import CameraResponse
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
    chromaticities = spaces.chromaticities(output_space, config)
    attributes: dict[str, object] = {
        "chromaticities": chromaticities,
        "adoptedNeutral": Float2(chromaticities[6], chromaticities[7]),
        "hdrio:colorSpace": spaces.canonical_space(output_space, config),
        "hdrio:ocioConfig": spaces.config_label(config),
        "hdrio:inputEncoding": f"{state.encoding.name} ({state.encoding_source})",
        "hdrio:whiteBalance": "camera",
    }
    interop = spaces.interop_id(output_space, config)
    if interop:
        attributes["colorInteropID"] = interop
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
