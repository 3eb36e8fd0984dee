"""Exposure merging (radiance maps from brackets and a camera response)."""

from hdrio.merge.debevec1997 import MERGE_METHODS, MergeStatistics, merge_brackets
from hdrio.merge.weighting import WEIGHTING_METHODS, weights_table

__all__ = ["MERGE_METHODS", "WEIGHTING_METHODS", "MergeStatistics", "merge_brackets",
           "weights_table"]
