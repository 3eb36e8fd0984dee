"""The merge job: brackets in, one scene-linear EXR (and a preview) out.

What it is asked (:mod:`~hdrio.job.options`), every setting resolved once
(:mod:`~hdrio.job.plan`), its stages in order (:mod:`~hdrio.job.run`, the stages in
:mod:`~hdrio.job.stages` and :mod:`~hdrio.job.radiance`), what it gives
(:mod:`~hdrio.job.result`) and what the EXR holds (:mod:`~hdrio.job.output`). Every front
end (the command line, the chain, the Blender add-on, a farm's worker) calls
:func:`~hdrio.job.run.merge_files`, :func:`~hdrio.job.run.merge_paths` or
:func:`~hdrio.job.run.merge_stack` (also :mod:`hdrio`'s own names, imported on first use).
"""
