"""The truth harness: hdrio against peers on brackets with known ground truth.

Real scene-linear photographs (``../shared/data/openexr_scenes``, or any EXR / .hdr)
are rendered into bracket stacks through real camera responses (DoRF, EMoR) with sensor
noise and quantisation; hdrio's variants, OpenCV and colour-hdri merge the same stacks
and are scored against the truth. ``python -m benchmarks.truth [--quick]``; see
docs/accuracy.md.

Modules: :mod:`.scenes` and :mod:`.curves` (the ground truth), :mod:`.stacks`
(rendering), :mod:`.config` (the designs), :mod:`.methods`, :mod:`.metrics`,
:mod:`.memory`, :mod:`.harness` (the loop) and :mod:`.report` (JSON, markdown, PNG).
"""

from pathlib import Path

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "results"
