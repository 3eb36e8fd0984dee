"""``python -m benchmarks.tonemap [--width W --height H --repeats N --json PATH]``.

Times hdrio's Reinhard (2002) global and local operators on a procedural HDR scene
(``hdrio.tools.synthetic.demo_scene``, float32 RGB) at W x H and at a quarter of each side, in
one run, against

* the floor: a plain copy of the same image (``numpy.copy``: read and write every byte);
* the peer: OpenCV's ``cv2.createTonemapReinhard`` where installed. It is a *different*
  operator (Reinhard & Devlin 2005, global only): a reference point for speed, not a
  like-for-like comparison;
* the reference: the numpy/scipy implementation these kernels replaced
  (``tests/reinhard2002_reference.py``), skipped with ``--no-reference``.

Every figure is the median of ``--repeats`` timed calls after one warm-up call (wall time,
and the process's CPU time, which shows how much the machine's other load took);
peak memory is measured on one more call. The JIT compile time is measured in fresh
processes: the first with an empty numba cache, the second reusing it. The machine's load
average is recorded before and after. Prints a table; writes JSON (default
``benchmarks/results/tonemap.json``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks.truth import DEFAULT_OUT
from benchmarks.truth.harness import environment
from benchmarks.truth.memory import PeakMemory
from benchmarks.truth.scenes import REPO_ROOT
from hdrio.io.write import write_text
from hdrio.tonemap.reinhard2002 import (
    tonemap_Reinhard2002_global,
    tonemap_Reinhard2002_local,
)
from hdrio.tools.synthetic import demo_scene

TARGETS_S = {"hdrio global": 0.3, "hdrio local": 3.0}  # issue #4's acceptance at 24 MP
_COMPILE_PROBE = """
import time
start = time.perf_counter()
import numpy as np
from hdrio.tonemap.reinhard2002 import tonemap_Reinhard2002_global, tonemap_Reinhard2002_local
import hdrio.tonemap.reinhard2002_kernels
from hdrio.radiometry.luminance import luminance_weights
luminance_weights()  # colour-science's import: not compile time
imported = time.perf_counter()
image = np.full((8, 8, 3), 0.5, dtype=np.float32)
tonemap_Reinhard2002_global(image)
tonemap_Reinhard2002_local(image)
print(imported - start, time.perf_counter() - imported)
"""


def opencv_reinhard() -> Callable[[np.ndarray], np.ndarray] | None:
    """OpenCV's Reinhard tone mapper on BGR float32, or ``None`` without OpenCV."""
    try:
        import cv2
    except ImportError:
        return None
    operator = cv2.createTonemapReinhard(gamma=1.0)
    return lambda rgb: operator.process(rgb[..., ::-1].copy())  # OpenCV wants BGR


def reference_operators() -> dict[str, Callable[[np.ndarray], np.ndarray]]:
    sys.path.insert(0, str(REPO_ROOT))
    from tests.reinhard2002_reference import reference_global, reference_local

    return {"reference global (numpy)": reference_global,
            "reference local (numpy/scipy)": reference_local}


def time_call(function: Callable[[np.ndarray], object], image: np.ndarray, repeats: int
              ) -> dict[str, float | None]:
    """Median and minimum wall time, median CPU time (s), and peak memory (MB)."""
    function(image)  # warm-up: caches, page faults of the allocator, lazy imports
    wall, cpu = [], []
    for _ in range(repeats):
        cpu_start, start = time.process_time(), time.perf_counter()
        function(image)
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - cpu_start)
    with PeakMemory() as memory:
        function(image)
    return {"median_s": statistics.median(wall), "min_s": min(wall),
            "cpu_median_s": statistics.median(cpu), "peak_mb": memory.peak_mb}


def compile_times() -> dict[str, float]:
    """First-call compile time with an empty numba cache, then with the cache it left."""
    result: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="hdrio-numba-cache-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache,
                   PYTHONPATH=os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")]))
        for label in ("cold_cache", "warm_cache"):
            output = subprocess.run([sys.executable, "-c", _COMPILE_PROBE], env=env,
                                    capture_output=True, text=True, check=True, cwd=REPO_ROOT)
            imported, first_calls = (float(v) for v in output.stdout.split())
            result[f"import_s_{label}"] = imported
            result[f"first_calls_s_{label}"] = first_calls
    return result


def run_size(width: int, height: int, repeats: int, with_reference: bool,
             progress: Callable[[str], None]) -> list[dict[str, object]]:
    image = demo_scene(height, width)
    methods: dict[str, Callable[[np.ndarray], object]] = {
        "floor: copy": np.copy,
        "hdrio global": tonemap_Reinhard2002_global,
        "hdrio local": tonemap_Reinhard2002_local,
    }
    peer = opencv_reinhard()
    if peer is not None:
        methods["OpenCV TonemapReinhard (other operator, global)"] = peer
    if with_reference:
        methods.update(reference_operators())
    rows = []
    for name, function in methods.items():
        progress(f"{width} x {height}: {name}")
        rows.append({"width": width, "height": height, "megapixels": width * height / 1e6,
                     "method": name, "repeats": repeats, **time_call(function, image, repeats)})
    by_name = {row["method"]: row for row in rows}
    floor = by_name["floor: copy"]["median_s"]
    peer_time = by_name.get("OpenCV TonemapReinhard (other operator, global)", {}).get("median_s")
    for row in rows:
        row["x_floor"] = row["median_s"] / floor
        row["x_opencv"] = row["median_s"] / peer_time if peer_time else None
        reference = by_name.get(row["method"].replace("hdrio global", "reference global (numpy)")
                                .replace("hdrio local", "reference local (numpy/scipy)"))
        row["speedup_vs_reference"] = (reference["median_s"] / row["median_s"]
                                       if reference and reference is not row else None)
    return rows


def table(rows: list[dict[str, object]]) -> str:
    def num(value: object, fmt: str) -> str:
        return format(value, fmt) if isinstance(value, float) else "-"

    lines = ["| size | method | median s | min s | CPU s | x floor | x OpenCV | "
             "x faster than reference | peak MB |", "|" + "---|" * 9]
    for r in rows:
        lines.append(f"| {r['width']}x{r['height']} | {r['method']} | {num(r['median_s'], '.3f')}"
                     f" | {num(r['min_s'], '.3f')} | {num(r['cpu_median_s'], '.3f')} | "
                     f"{num(r['x_floor'], '.1f')} | {num(r['x_opencv'], '.2f')} | "
                     f"{num(r['speedup_vs_reference'], '.1f')} | {num(r['peak_mb'], '.0f')} |")
    return "\n".join(lines)


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.tonemap",
                                     description=__doc__.split("\n\n")[1])
    parser.add_argument("--width", type=int, default=6000, help="image width (default 6000)")
    parser.add_argument("--height", type=int, default=4000, help="image height (default 4000)")
    parser.add_argument("--repeats", type=int, default=5, help="timed calls (median; default 5)")
    parser.add_argument("--json", type=Path, default=DEFAULT_OUT / "tonemap.json",
                        help="JSON output (default benchmarks/results/tonemap.json)")
    parser.add_argument("--no-reference", action="store_true",
                        help="skip the slow numpy/scipy reference implementation")
    parser.add_argument("--no-compile", action="store_true",
                        help="skip measuring compile time in fresh processes (~40 s)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.width < 1 or args.height < 1 or args.repeats < 1:
        print("error: --width, --height and --repeats must be positive", file=sys.stderr)
        return 2
    if not args.json.parent.is_dir():
        print(f"error: --json {args.json}: folder {args.json.parent} does not exist",
              file=sys.stderr)
        return 2
    load_before = os.getloadavg()
    compile_info: dict[str, float] = {}
    if not args.no_compile:
        print("compile (fresh processes, empty then warm numba cache) ...", flush=True)
        compile_info = compile_times()
    rows = []
    for width, height in ((args.width, args.height),
                          (max(1, args.width // 4), max(1, args.height // 4))):
        rows += run_size(width, height, args.repeats, not args.no_reference,
                         lambda message: print(message, flush=True))
    load_after = os.getloadavg()
    results = {"command": "python -m benchmarks.tonemap " + " ".join(argv if argv is not None
                                                                      else sys.argv[1:]),
               "environment": environment(), "threads": _kernel_threads(),
               "load_average_before": load_before, "load_average_after": load_after,
               "compile": compile_info, "targets_s": TARGETS_S, "rows": rows}
    text = json.dumps(results, indent=1) + "\n"
    write_text(args.json, text)  # atomic: no half-written JSON
    print()
    print(table(rows))
    if compile_info:
        print(f"\ncompile: first calls {compile_info['first_calls_s_cold_cache']:.1f} s with "
              f"an empty cache, {compile_info['first_calls_s_warm_cache']:.2f} s from the "
              f"cache (import {compile_info['import_s_warm_cache']:.2f} s)")
    print(f"load average (1, 5, 15 min): before {_load(load_before)}, after "
          f"{_load(load_after)} on {os.cpu_count()} CPUs; kernel threads {_kernel_threads()}")
    for name, target in TARGETS_S.items():
        big = next(r for r in rows if r["method"] == name)
        if big["megapixels"] >= 24.0:  # the targets are stated for 24 MP
            verdict = "meets" if big["median_s"] < target else "misses"
            print(f"{name} at {big['width']}x{big['height']}: median {big['median_s']:.3f} s "
                  f"(CPU {big['cpu_median_s']:.3f} s), {verdict} the {target} s target")
    print(f"wrote {args.json}")
    return 0


def _load(values: tuple[float, float, float]) -> str:
    return ", ".join(f"{v:.2f}" for v in values)


def _kernel_threads() -> int:
    from hdrio.parallel import threads

    return threads()


if __name__ == "__main__":
    sys.exit(main())
