"""Exposure merging: brackets and a camera response in, a radiance map out.

The fused kernel (:mod:`~hdrio.merge.kernel`) behind one weighted mean
(:mod:`~hdrio.merge.weighted_mean`) that every estimator shares, the merge functions by
estimator name (:mod:`~hdrio.merge.methods`), the saturation policy, highlights, masked
re-merges (deghosting, exclusions), ND filters and exposures checked against the data.
The tables they read (curve, noise, weights) are :mod:`hdrio.radiometry`'s.
"""

from hdrio.merge.methods import MERGE_METHODS
from hdrio.merge.weighted_mean import MergeStatistics, merge_brackets

__all__ = ["MERGE_METHODS", "MergeStatistics", "merge_brackets"]
