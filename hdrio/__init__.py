"""hdrio: bracketed exposures to scene-linear OpenEXR, with colour management.

Subpackages are imported here in dependency order, which documents the layering: the
data model, I/O, weighting and response recovery, merging, tone mapping, then the
pipeline that chains them. ``hdrio`` never imports ``bpy``, ``plugins`` or ``hdrio.cli``.
"""

__version__ = "0.1.0"

import warnings  # noqa: E402

# colour-science warns on import, three lines on stderr, when matplotlib is absent; hdrio
# needs matplotlib only for its pictures (the plot extra), which say so when it is missing.
warnings.filterwarnings("ignore", message='"Matplotlib" related API features are not '
                                          "available")

from hdrio.errors import HdrioError, InputError, ResponseSolveError  # noqa: E402
from hdrio.io import read_brackets, write_exr  # noqa: E402
from hdrio.merge import MERGE_METHODS, WEIGHTING_METHODS, merge_brackets  # noqa: E402
from hdrio.pipeline import MergeOptions, MergeResult, merge_files, merge_stack  # noqa: E402
from hdrio.response import RESPONSE_METHODS, CameraResponse, response_Debevec1997  # noqa: E402
from hdrio.stack import ExposureStack  # noqa: E402
from hdrio.tonemap import TONEMAP_METHODS  # noqa: E402

__all__ = [
    "MERGE_METHODS", "RESPONSE_METHODS", "TONEMAP_METHODS", "WEIGHTING_METHODS",
    "CameraResponse", "ExposureStack", "HdrioError", "InputError", "MergeOptions",
    "MergeResult", "ResponseSolveError", "merge_brackets", "merge_files", "merge_stack",
    "read_brackets", "response_Debevec1997", "write_exr",
]
