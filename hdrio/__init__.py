"""hdrio: bracketed exposures to scene-linear OpenEXR, with colour management.

``hdrio`` never imports ``bpy``, ``plugins`` or ``hdrio.cli``.
"""

__version__ = "0.1.0"

import warnings  # noqa: E402

# colour-science warns on import, three lines on stderr, when matplotlib is absent; hdrio
# needs matplotlib only for its pictures (the plot extra), which say so when it is missing.
warnings.filterwarnings("ignore", message='"Matplotlib" related API features are not '
                                          "available")

from hdrio.lazy import lazy_attributes  # noqa: E402

# Public names and their modules, in dependency order (the layers, bottom to top:
# foundations, I/O, radiometry, the stages side by side, the job that chains them;
# docs/architecture.md). Each is imported on first use, so a command pays only for what
# it runs.
_EXPORTS = {
    "ExposureStack": "hdrio.stack",
    "HdrioError": "hdrio.errors", "InputError": "hdrio.errors",
    "ResponseSolveError": "hdrio.errors",
    "read_brackets": "hdrio.io.brackets", "write_exr": "hdrio.io.write",
    "CameraResponse": "hdrio.radiometry.curve",
    "NoiseModel": "hdrio.radiometry.noise",
    "ESTIMATORS": "hdrio.radiometry.estimators",
    "WEIGHTING_METHODS": "hdrio.radiometry.weighting",
    "RESPONSE_METHODS": "hdrio.response", "response_Debevec1997": "hdrio.response",
    "MERGE_METHODS": "hdrio.merge.methods", "merge_brackets": "hdrio.merge.weighted_mean",
    "TONEMAP_METHODS": "hdrio.tonemap",
    "MergeOptions": "hdrio.job.options", "MergePlan": "hdrio.job.plan",
    "plan_merge": "hdrio.job.plan", "MergeResult": "hdrio.job.result",
    "merge_files": "hdrio.job.run", "merge_paths": "hdrio.job.run",
    "merge_stack": "hdrio.job.run",
}
__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_attributes(__name__, _EXPORTS)
