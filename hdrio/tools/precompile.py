"""``python -m hdrio.tools.precompile STAGE ...``: compile a job's kernels into numba's disk
cache in a process of their own, started by :func:`hdrio.jit.compile_ahead` on a first
run. Each stage runs hdrio's own entry point on a tiny input, so the kernels compile for
the very types the job passes them. Only :mod:`hdrio.jit` imports this module (a job on
two or three CPUs compiles the preview's stage here while it waits for a helper)."""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

import numpy as np

from hdrio.parallel import die_with_parent


def _compile_merge() -> None:
    """The merge kernel of 8-bit RGB brackets (the pair-table path, JPEG's), the noise
    fit's look for clipped neighbours, and the write's conversion of RGB to half and the
    check that counts its pieces."""
    from hdrio.cms.checks import StreamingCheck
    from hdrio.io.half import to_half
    from hdrio.merge.weighted_mean import merge_brackets
    from hdrio.radiometry.noise_fit import near_clipping
    from hdrio.stack import ExposureStack
    from hdrio.tools.synthetic import gamma_inverse_response

    codes = np.arange(2 * 4 * 4 * 3, dtype=np.uint8).reshape(2, 4, 4, 3)
    stack = ExposureStack.from_arrays(codes, [0.25, 1.0])
    merge_brackets(stack, gamma_inverse_response()[0], domain="linear")
    near_clipping(codes, 2, 250)
    to_half(np.ones((2, 2, 3), np.float32), [1.0] * 3, [0.0] * 3, [1.0] * 3,
            StreamingCheck(compiled=True).add)


def _compile_response() -> None:
    """The clip test of the response's samples (8-bit RGB), which the solve's filter
    runs where a stack mixes its channels after the clip."""
    from types import SimpleNamespace

    from hdrio.radiometry.cliptest import dropped_observations, untested

    codes = np.arange(2 * 16 * 3, dtype=np.uint8).reshape(2, 16, 3)
    dropped_observations(codes, SimpleNamespace(kernel_args=lambda: untested(255, 3)))


def _compile_motion() -> None:
    """Alignment's still check and deghosting's test of 8-bit RGB brackets, through the
    pipeline's own steps on a small still stack (what ``auto`` runs on most stacks)."""
    from hdrio.align.motion import align_step, deghost_step
    from hdrio.stack import ExposureStack
    from hdrio.tools.synthetic import demo_scene, gamma_inverse_response, render_brackets

    times = [1 / 256, 1 / 16, 1.0]
    stack = ExposureStack.from_arrays(render_brackets(demo_scene(96, 128), times), times)
    response = gamma_inverse_response()[0]
    stack, response, motion = align_step(stack, response, "auto", None)
    deghost_step(stack, response, motion, "auto", None)


def _compile_preview(operator: str) -> None:
    from hdrio.tonemap.preview import render_preview

    render_preview(np.full((8, 8, 3), 0.5, np.float32), operator)


def compile_stage(stage: str) -> str | None:
    """Compile one stage (``merge``, ``motion``, ``response``, ``preview=OPERATOR``) into the
    disk cache in this process; its name, or None for anything else."""
    name, _, value = stage.partition("=")
    if name == "merge":
        _compile_merge()
    elif name == "response":
        _compile_response()
    elif name == "motion":
        _compile_motion()
    elif name == "preview":
        _compile_preview(value)
    else:
        return None
    return name


def main(argv: Sequence[str]) -> int:
    """``python -m hdrio.tools.precompile [nice=N] merge motion response preview=OPERATOR``: compile
    those kernels in that order (at niceness ``N`` when given; and stop when the process
    that started this one stops), printing each stage's name (``merge``, ``motion``,
    ``preview``) once its kernels are in the cache."""
    die_with_parent(os.getppid())
    for stage in argv:
        name, _, value = stage.partition("=")
        if name == "nice":  # the job needs this stage later than others: yield to them
            os.nice(int(value))
        elif compile_stage(stage) is not None:
            print(name, flush=True)  # hdrio.jit waits for this line
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
