"""First-call compile time of every numba kernel; a second process reuses the disk cache."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

# Times the first whole merge in a fresh interpreter: every numba kernel of `hdrio merge`
# (bracket classification, sampling, the solve's normal equations, the merge) and of its
# preview (Reinhard) compiled (or loaded from the cache), plus a tiny merge.
_PROBE = """
import json, sys, tempfile, time
from pathlib import Path
from hdrio.io.write import write_image
from hdrio.job.run import merge_files
from benchmarks.speed.scene import bracket_stack
stack, _ = bracket_stack(64, 96, count=3)
folder = Path(tempfile.mkdtemp())
paths = [write_image(folder / f"b{j}.png", codes, "uint8") for j, codes in enumerate(stack.codes)]
exposures = [repr(float(t)) for t in stack.exposures]
def merge():
    merge_files(paths, folder / "out.exr", exposures=exposures, preview=folder / "p.jpg",
                tonemap="reinhard-local")
start = time.perf_counter()
merge()
first = time.perf_counter() - start
start = time.perf_counter()
merge()
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
        {"row": "jit", "method": "first hdrio merge + local preview, new process, empty "
                                 "cache (compiles every kernel)", "seconds": cold["first"]},
        {"row": "jit", "method": "first hdrio merge + local preview, second process, "
                                 "cache reused", "seconds": warm["first"],
         "cache_files": len(cached_files)},
        {"row": "jit", "method": "second hdrio merge + local preview, same process (warm)",
         "seconds": warm["second"]},
    ]
