"""Radiometry: what a code value says about light, read by every stage above it.

The camera's inverse response (:mod:`~hdrio.radiometry.curve`, and one saved in an EXR
header, :mod:`~hdrio.radiometry.saved_response`), the noise model of each observation
(:mod:`~hdrio.radiometry.noise`), code weightings (:mod:`~hdrio.radiometry.weighting`),
the merge estimators' weights and domains (:mod:`~hdrio.radiometry.estimators`), the
per-bracket tables the merges read (:mod:`~hdrio.radiometry.tables`) and the luminance
of an RGB colour space (:mod:`~hdrio.radiometry.luminance`).

Layering: this package imports only the foundations and :mod:`hdrio.io`; the response
solvers, alignment, merging, tone mapping and colour management import it, and it
imports none of them.
"""

from hdrio.lazy import lazy_attributes

_EXPORTS = {
    "CameraResponse": "hdrio.radiometry.curve", "linear_response": "hdrio.radiometry.curve",
    "NoiseModel": "hdrio.radiometry.noise", "fit_noise": "hdrio.radiometry.noise",
    "observation_variance": "hdrio.radiometry.noise",
    "ESTIMATORS": "hdrio.radiometry.estimators", "Estimator": "hdrio.radiometry.estimators",
    "WEIGHTING_METHODS": "hdrio.radiometry.weighting",
    "weights_table": "hdrio.radiometry.weighting",
    "read_response": "hdrio.radiometry.saved_response",
    "luminance": "hdrio.radiometry.luminance",
}
__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_attributes(__name__, _EXPORTS)
