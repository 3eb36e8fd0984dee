"""The plan of a merge: every setting of :class:`~hdrio.job.options.MergeOptions` resolved
once, before any pixel is read, into what the stages read.

The one place that decides which estimator merges (its domain, whether its weights read
the noise model), whether the job fits a noise model at all, which skips are in force and
whether alignment or deghosting run. The stages (:mod:`hdrio.job.stages`), the output
(:mod:`hdrio.job.output`) and the Blender add-on's baked merge ask the plan; none of them
looks an option up again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hdrio.align import ALIGN_MODES, DEGHOST_MODES
from hdrio.job.options import MergeOptions
from hdrio.merge.highlights import HIGHLIGHT_MODES
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.estimators import ESTIMATORS, Estimator
from hdrio.radiometry.noise import NoiseModel
from hdrio.skips import SKIPS


@dataclass(frozen=True)
class MergePlan:
    """What a merge will do, resolved from its options.

    Attributes
    ----------
    options
        The options it was made from (recorded in the header).
    estimator
        The merge estimator (``--merge``): its canonical name, domain and weights.
    skips
        The skips in force (:data:`hdrio.skips.SKIPS` less ``--no-skip``).
    """

    options: MergeOptions
    estimator: Estimator
    skips: frozenset[str]

    @property
    def fits_noise(self) -> bool:
        """Whether the job fits the stack's noise model: the estimator's weights read it,
        or ``--uncertainty`` predicts each pixel's deviation from it."""
        return self.estimator.needs_noise or self.options.uncertainty

    @property
    def aligns(self) -> bool:
        return self.options.align != "off"

    @property
    def deghosts(self) -> bool:
        return self.options.deghost != "off"

    def weight_tables(self, response: CameraResponse, exposures,
                      noise: NoiseModel | None) -> np.ndarray:
        """The weights the estimator merges with, ``(P or 1, C, levels)``, zero at
        ``Z_max`` (:meth:`hdrio.radiometry.estimators.Estimator.weight_tables`)."""
        return self.estimator.weight_tables(response, exposures, self.options.weighting, noise)


def plan_merge(options: MergeOptions) -> MergePlan:
    """Resolve ``options`` once; raise ``ValueError`` naming the option when a mode or
    method is unknown (``KeyError`` listing the choices for ``--merge``)."""
    if options.align not in ALIGN_MODES:
        raise ValueError(f"--align must be one of {', '.join(ALIGN_MODES)}, "
                         f"not {options.align!r}")
    if options.deghost not in DEGHOST_MODES:
        raise ValueError(f"--deghost must be one of {', '.join(DEGHOST_MODES)}, "
                         f"not {options.deghost!r}")
    if options.highlights not in HIGHLIGHT_MODES:
        raise ValueError(f"highlights {options.highlights!r}: choose from "
                         f"{', '.join(HIGHLIGHT_MODES)}")
    return MergePlan(options, ESTIMATORS[options.merge],
                     frozenset(SKIPS) - set(options.no_skip))
