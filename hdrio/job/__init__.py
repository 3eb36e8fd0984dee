"""The merge job: brackets in, one scene-linear EXR (and a preview) out.

What it is asked (:mod:`~hdrio.job.options`), every setting resolved once
(:mod:`~hdrio.job.plan`), its stages in order (:mod:`~hdrio.job.run`, the stages in
:mod:`~hdrio.job.stages` and :mod:`~hdrio.job.radiance`), what it gives
(:mod:`~hdrio.job.result`) and what the EXR holds (:mod:`~hdrio.job.output`). Every front
end (the command line, the chain, the Blender add-on, a farm's worker) calls
:func:`~hdrio.job.run.merge_files`, :func:`~hdrio.job.run.merge_paths` or
:func:`~hdrio.job.run.merge_stack`.
"""

from hdrio.lazy import lazy_attributes

_EXPORTS = {
    "MergeOptions": "hdrio.job.options", "MergePlan": "hdrio.job.plan",
    "plan_merge": "hdrio.job.plan", "MergeResult": "hdrio.job.result",
    "merge_files": "hdrio.job.run", "merge_paths": "hdrio.job.run",
    "merge_stack": "hdrio.job.run",
}
__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_attributes(__name__, _EXPORTS)
