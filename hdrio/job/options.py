"""What a merge job is asked: :class:`MergeOptions`, every field recorded in the EXR
header. The same names and meanings in ``hdrio merge``, the chain and the Blender add-on.

:func:`hdrio.job.plan.plan_merge` resolves them once into what the stages read.
"""

from __future__ import annotations

from dataclasses import dataclass

from hdrio.cms.calibration import Calibration, Region
from hdrio.cms.spaces import DEFAULT_WORKING_SPACE
from hdrio.merge.nd import NDFilter
from hdrio.numbers import MERGE_NUMBERS, check_fields
from hdrio.radiometry.luminance import DEFAULT_SPACE


@dataclass(frozen=True)
class MergeOptions:
    """How to turn a stack into radiance; every field is recorded in the EXR header."""

    response: str = "Debevec1997"
    smoothing: float = 50.0
    # The paper's triangle (zero at both ends) rather than the tutorial's never-zero hat:
    # the hat lets saturated and black observations pull g(255) and g(0) and leak into
    # the merge (median error 6 % against 1.2 % on the demo; see docs/method.md).
    weighting: str = "Debevec1997"
    sampling: str = "stratified"
    samples: int | None = None
    # Inverse-variance weights from the stack's own noise model (hdrio.radiometry.estimators):
    # on the truth harness's core stacks median error 1.03 % against 1.25 % for the
    # tutorial's log-domain triangle-weighted mean ("log"), p99 3.4 % against 4.8 %.
    merge: str = "inverse-variance"
    # "auto": a partly clipped observation is dropped whole where its other channels
    # disagree with the next shorter bracket's by more than noise (a clip before a
    # camera's colour matrix), else its clipped channels alone (hdrio/merge/saturation.py,
    # hdrio/radiometry/cliptest.py).
    saturation: str = "auto"
    exclude_colour: tuple[int, ...] | None = None
    # --mask files (hdrio.io.masks): kept out of the solve, registration and the merge,
    # as the colour.
    masks: tuple[str, ...] = ()
    # Merge with each bracket's exposure estimated from the data (hdrio.merge.exposure_check);
    # the metadata's are checked against the data's either way.
    exposures_from_data: bool = False
    # --nd: brackets shot through a neutral-density filter (hdrio.merge.nd).
    nd: tuple[NDFilter, ...] = ()
    seed: int = 0
    # colour-science name of the radiance's primaries: set from the input encoding.
    colourspace: str = DEFAULT_SPACE
    # Colour management (hdrio.cms): see docs/colour.md.
    input_encoding: str | None = None  # when the files do not say; None: sRGB
    output_space: str = DEFAULT_WORKING_SPACE  # OpenColorIO name of the EXR's space
    ocio_config: str | None = None  # path or ocio:// URI; None: $OCIO, else built-in
    calibration: Calibration | None = None  # None: relative radiance
    white_balance: Region | None = None  # neutral region x, y, w, h; None: camera's
    # Camera RAW white-balance multipliers R, G, B for the set; None: as shot.
    raw_multipliers: tuple[float, float, float] | None = None
    # A saved response (an EXR written by hdrio) instead of a solve: hdrio.skips.
    response_from: str | None = None
    # Names in hdrio.skips.SKIPS turned off (all on by default).
    no_skip: tuple[str, ...] = ()
    # Also predict each pixel's relative standard deviation (hdrio.merge.uncertainty),
    # written as the EXR layer "uncertainty".
    uncertainty: bool = False
    # Registration and deghosting (hdrio.align): docs/motion.md.
    # auto | off | translation | euclidean | homography.
    align: str = "auto"
    # auto | off.
    deghost: str = "auto"
    motion_layer: bool = False  # the deghosting mask as an EXR channel "motion.Y"
    clip_mask: bool = False  # pixels clipped in every bracket as an EXR channel "clipped.Y"
    # clip | reconstruct: channels clipped in every bracket estimated from the unclipped
    # ones and the neighbours' colour (hdrio.merge.highlights); clip leaves the bounds.
    highlights: str = "clip"

    def __post_init__(self) -> None:
        check_fields(self, MERGE_NUMBERS)  # --lambda, --samples, --seed: before any work
