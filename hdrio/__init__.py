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

# Public names and their modules, in dependency order (the layering: the data model, I/O,
# weighting and response recovery, merging, tone mapping, then the pipeline that chains
# them). Each is imported on first use, so a command pays only for what it runs.
_EXPORTS = {
    "ExposureStack": "hdrio.stack",
    "HdrioError": "hdrio.errors", "InputError": "hdrio.errors",
    "ResponseSolveError": "hdrio.errors",
    "read_brackets": "hdrio.io.brackets", "write_exr": "hdrio.io.write",
    "RESPONSE_METHODS": "hdrio.response", "CameraResponse": "hdrio.response",
    "response_Debevec1997": "hdrio.response",
    "MERGE_METHODS": "hdrio.merge.estimators", "WEIGHTING_METHODS": "hdrio.merge.weighting",
    "merge_brackets": "hdrio.merge.debevec1997",
    "TONEMAP_METHODS": "hdrio.tonemap",
    "MergeOptions": "hdrio.merge_job", "MergeResult": "hdrio.merge_job",
    "merge_files": "hdrio.pipeline", "merge_stack": "hdrio.pipeline",
}
__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_attributes(__name__, _EXPORTS)
