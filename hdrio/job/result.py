"""What a merge job gives (:class:`MergeResult`) and the clock of its phases.

:mod:`hdrio.job.output` turns a result into the EXR's pixels, layers and header.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hdrio.align.motion import Motion
from hdrio.cms.checks import dynamic_range_stops
from hdrio.cms.colour_stage import ColourState
from hdrio.job.options import MergeOptions
from hdrio.job.plan import MergePlan
from hdrio.merge.exposure_check import ExposureCheck
from hdrio.merge.highlights import HighlightReport
from hdrio.merge.nd import NDReport
from hdrio.merge.weighted_mean import MergeStatistics
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.luminance import luminance
from hdrio.radiometry.noise import NoiseModel
from hdrio.skips import SkipReport
from hdrio.stack import ExposureStack

Progress = Callable[[str], None]


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
    plan: MergePlan
    """The settings the stages ran with, resolved once from ``options``."""
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
    motion_test_exposures: np.ndarray | None = None
    """The data's exposures, which deghosting's test read instead of the merge's
    (:meth:`~hdrio.merge.exposure_check.ExposureCheck.for_the_motion_test`), else
    ``None``."""
    nd: NDReport | None = None
    unseen: np.ndarray | None = None
    """``(H, W)`` bool: excluded in every bracket (radiance 0, alpha 0), else ``None``."""
    highlights: HighlightReport | None = None
    """What ``--highlights reconstruct`` changed (``None``: not asked, or nothing clipped)."""

    def add_timings(self, clock: PhaseClock) -> None:
        """Add the phases ``clock`` timed outside the stages (reading, writing, the
        preview) to :attr:`timings` and :attr:`cpu_timings`."""
        for phase, seconds in clock.wall.items():
            self.timings[phase] = self.timings.get(phase, 0.0) + seconds
        for phase, seconds in clock.cpu.items():
            self.cpu_timings[phase] = self.cpu_timings.get(phase, 0.0) + seconds

    @property
    def dynamic_range_stops(self) -> tuple[float, float]:
        """``(full, robust)``: log2 of max/min luminance, and of its 99.9/0.1 percentiles."""
        return dynamic_range_stops(luminance(self.radiance, self.options.colourspace))
