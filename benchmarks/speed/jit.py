"""First-call compile time of the numba kernels; a second process reuses the disk cache."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

# Times the first merge in a fresh interpreter: compile (or cache load) plus a tiny merge.
_PROBE = """
import json, time
import numpy as np
from hdrio.merge.debevec1997 import merge_brackets
from benchmarks.speed.scene import bracket_stack, true_response
stack, _ = bracket_stack(64, 96, count=3)
response = true_response()
start = time.perf_counter()
merge_brackets(stack, response)
first = time.perf_counter() - start
start = time.perf_counter()
merge_brackets(stack, response)
print(json.dumps({"first": first, "second": time.perf_counter() - start}))
"""


def _probe(cache: Path) -> dict:
    environment = {"NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(Path.cwd())}
    completed = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                               env={**os.environ, **environment}, check=True)
    return json.loads(completed.stdout.strip().splitlines()[-1])


def run() -> list[dict]:
    """Two fresh processes sharing an empty cache folder: the first compiles, the second loads."""
    with tempfile.TemporaryDirectory(prefix="hdrio-numba-cache-") as folder:
        cold = _probe(Path(folder))
        cached_files = sorted(p.suffix for p in Path(folder).rglob("*") if p.is_file())
        warm = _probe(Path(folder))
    return [
        {"row": "jit", "method": "first merge, new process, empty cache (compile)",
         "seconds": cold["first"]},
        {"row": "jit", "method": "first merge, second process, cache reused",
         "seconds": warm["first"], "cache_files": len(cached_files)},
        {"row": "jit", "method": "second merge in the same process (warm)",
         "seconds": warm["second"]},
    ]
