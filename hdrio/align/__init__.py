"""Registration of brackets and deghosting: each bracket in, a transform and a mask out.

Modules, one per method: :mod:`~hdrio.align.ward2003` (median threshold bitmaps),
:mod:`~hdrio.align.lucaskanade` (sub-pixel refinement), :mod:`~hdrio.align.warp`
(resampling codes), :mod:`~hdrio.align.registration` (the stack's alignment),
:mod:`~hdrio.align.quick` (is anything moving?), :mod:`~hdrio.align.resolve` (the aligned
sample a response is re-solved on), :mod:`~hdrio.align.comparametric` (what the
consistency test compares), :mod:`~hdrio.align.consistency` (the test, per cell),
:mod:`~hdrio.align.deghost` (which bracket's view each moving region keeps).
``hdrio.job.run`` calls them through :mod:`~hdrio.align.motion`.
"""

ALIGN_MODES = ("auto", "off", "translation", "euclidean", "homography")
"""``--align``: ``auto`` measures and warps only brackets that moved; ``off``; or a model."""

DEGHOST_MODES = ("auto", "off")
"""``--deghost``."""

REFERENCE_RULE = "the longest well-exposed bracket at the most pixels"
"""Which bracket the others are registered to
(:func:`hdrio.align.registration.reference_bracket`), in the words README, ``--align``'s
help and the summary all use."""
