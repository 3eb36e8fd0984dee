"""First run: kernels compiled ahead in a helper process land in the disk cache that the
job then loads (it does not compile them a second time)."""

from __future__ import annotations

import os
import subprocess
import sys

_CACHED = """
import sys
from hdrio import jit
print(" ".join(f"{stage}={jit.is_stage_cached(stage)}" for stage in sys.argv[1:]))
"""


def _run(code_or_module: list[str], cache: str) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    return subprocess.run([sys.executable, *code_or_module], capture_output=True, text=True,
                          env=env, check=True, timeout=600).stdout.strip()


def test_compile_ahead_fills_the_cache_the_job_reads(tmp_path):
    cache = str(tmp_path / "numba-cache")
    stages = ["merge", "motion", "preview"]
    assert _run(["-c", _CACHED, *stages], cache) == "merge=False motion=False preview=False"
    _run(["-m", "hdrio.precompile", "merge", "motion", "preview=reinhard-global"], cache)
    # A new process finds every kernel of those stages in the cache: the job's merge,
    # alignment, deghosting and preview load them instead of compiling.
    assert _run(["-c", _CACHED, *stages], cache) == "merge=True motion=True preview=True"


def test_a_first_merge_says_it_compiles_only_what_is_not_cached(tmp_path, brackets):
    cache = str(tmp_path / "numba-cache")
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    command = [sys.executable, "-m", "hdrio", "merge", *map(str, brackets), "-o",
               str(tmp_path / "out.exr"), "--preview", str(tmp_path / "out.jpg")]
    first = subprocess.run(command, capture_output=True, text=True, env=env, timeout=900)
    assert first.returncode == 0, first.stderr
    # The response compiles here; the merge, alignment and deghosting, and preview
    # kernels were compiled meanwhile by the helper processes, so the job loads them and
    # says nothing of them (the report's check is NumPy: nothing to compile).
    assert "compiling kernels (first run only): response" in first.stderr
    for stage in ("merge", "motion", "preview"):
        assert f"compiling kernels (first run only): {stage}" not in first.stderr
    second = subprocess.run(command, capture_output=True, text=True, env=env, timeout=900)
    assert second.returncode == 0 and "compiling kernels" not in second.stderr
