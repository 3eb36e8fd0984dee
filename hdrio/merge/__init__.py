"""Exposure merging (radiance maps from brackets and a camera response)."""

from hdrio.merge.debevec1997 import MergeStatistics, merge_brackets
from hdrio.merge.estimators import MERGE_METHODS, merge_weights
from hdrio.merge.noise import NoiseModel, fit_noise, observation_variance
from hdrio.merge.weighting import WEIGHTING_METHODS, weights_table

__all__ = ["MERGE_METHODS", "WEIGHTING_METHODS", "MergeStatistics", "NoiseModel", "fit_noise",
           "merge_brackets", "merge_weights", "observation_variance", "weights_table"]
