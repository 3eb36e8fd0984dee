"""A merge job's terms: what it is asked (:class:`MergeOptions`, every field recorded in
the EXR header), the clock of its phases and what it gives (:class:`MergeResult`).

:mod:`hdrio.pipeline` runs the job; :mod:`hdrio.merge_output` turns its result into the
EXR's pixels, layers and header.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hdrio.align.stage import Motion
from hdrio.cms.calibration import Calibration, Region
from hdrio.cms.checks import dynamic_range_stops
from hdrio.cms.luminance import DEFAULT_SPACE, luminance
from hdrio.cms.spaces import DEFAULT_WORKING_SPACE
from hdrio.cms.stage import ColourState
from hdrio.merge.debevec1997 import MergeStatistics
from hdrio.merge.exposures import ExposureCheck
from hdrio.merge.highlights import HighlightReport
from hdrio.merge.nd import NDFilter, NDReport
from hdrio.merge.noise import NoiseModel
from hdrio.numbers import MERGE_NUMBERS, check_fields
from hdrio.response import CameraResponse
from hdrio.skips import SKIPS, SkipReport
from hdrio.stack import ExposureStack

Progress = Callable[[str], None]


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
    # Inverse-variance weights from the stack's own noise model (hdrio.merge.estimators):
    # on the truth harness's core stacks median error 1.03 % against 1.25 % for the
    # tutorial's log-domain triangle-weighted mean ("log"), p99 3.4 % against 4.8 %.
    merge: str = "inverse-variance"
    # "auto": a partly clipped observation is dropped whole where its other channels
    # disagree with the next shorter bracket's by more than noise (a clip before a
    # camera's colour matrix), else its clipped channels alone (hdrio/merge/saturation.py,
    # hdrio/merge/cliptest.py).
    saturation: str = "auto"
    exclude_colour: tuple[int, ...] | None = None
    # --mask files (hdrio.io.masks): kept out of the solve and the merge, as the colour.
    masks: tuple[str, ...] = ()
    # Merge with each bracket's exposure estimated from the data (hdrio.merge.exposures);
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

    @property
    def skips(self) -> frozenset[str]:
        """The skips (:mod:`hdrio.skips`) in force."""
        return frozenset(SKIPS) - set(self.no_skip)


class PhaseClock:
    """Wall-clock and CPU seconds per phase of a run: :meth:`lap` adds the time since
    the last lap (or the start) to a phase."""

    def __init__(self) -> None:
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}
        self._wall, self._cpu = time.perf_counter(), time.process_time()

    def lap(self, phase: str) -> None:
        wall, cpu = time.perf_counter(), time.process_time()
        self.wall[phase] = self.wall.get(phase, 0.0) + wall - self._wall
        self.cpu[phase] = self.cpu.get(phase, 0.0) + cpu - self._cpu
        self._wall, self._cpu = wall, cpu


@dataclass
class MergeResult:
    stack: ExposureStack
    response: CameraResponse
    radiance: np.ndarray
    statistics: MergeStatistics
    options: MergeOptions
    timings: dict[str, float] = field(default_factory=dict)
    """Wall-clock seconds per phase (``response``, ``align``, ``deghost``, ``merge``, ...)."""
    cpu_timings: dict[str, float] = field(default_factory=dict)
    """The same phases' CPU seconds (``time.process_time``: every thread of the process),
    which a loaded machine inflates less than the wall clock (the benchmarks' ratios)."""
    exposure_scale: float = 1.0
    colour: ColourState | None = None
    skipped: SkipReport = field(default_factory=SkipReport)
    noise: NoiseModel | None = None
    uncertainty: np.ndarray | None = None
    """``sigma_E / E`` per pixel and channel (``--uncertainty``), else ``None``."""
    motion: Motion = field(default_factory=Motion)
    exposures: ExposureCheck | None = None
    """The metadata's exposures against the data's (three brackets or more)."""
    nd: NDReport | None = None
    unseen: np.ndarray | None = None
    """``(H, W)`` bool: excluded in every bracket (radiance 0, alpha 0), else ``None``."""
    highlights: HighlightReport | None = None
    """What ``--highlights reconstruct`` changed (``None``: not asked, or nothing clipped)."""

    @property
    def dynamic_range_stops(self) -> tuple[float, float]:
        """``(full, robust)``: log2 of max/min luminance, and of its 99.9/0.1 percentiles."""
        return dynamic_range_stops(luminance(self.radiance, self.options.colourspace))
