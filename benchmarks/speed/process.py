"""The commands a user types, timed as processes: wall time and peak RSS from the OS.

Each row runs one command in a fresh process (:func:`timed`: wall seconds, CPU seconds
and the peak resident memory of that process, as the kernel counts them), so start-up,
imports, the kernel cache load and everything the command does around its core are in.
The I/O floor is a process too: a plain OpenImageIO script that decodes the same JPEGs
and writes one half ZIP EXR, timed in the same run. It writes the very pixels hdrio wrote
(loaded from a ``.npy`` file), since what an EXR costs to compress depends on what is in
it; the older floor, which wrote the JPEG values (256 levels) instead, is still reported
beside it, labelled (measured here, the two take about the same time). CPU seconds
(user + system, all threads) are recorded too: on a shared machine they move less than
wall time.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.speed.endtoend import write_jpegs
from benchmarks.speed.scene import bracket_stack
from hdrio.io.images import read_image

_MEASURE = """
import json, os, resource, subprocess, sys, time
cores = int(sys.argv[1])
if cores:
    os.sched_setaffinity(0, range(cores))
start = time.perf_counter()
completed = subprocess.run(sys.argv[2:], capture_output=True, text=True)
seconds = time.perf_counter() - start
usage = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({"returncode": completed.returncode, "seconds": seconds,
                  "peak_mb": usage.ru_maxrss / 1024,
                  "cpu_seconds": usage.ru_utime + usage.ru_stime,
                  "output": completed.stdout + completed.stderr}))
"""
_FLOOR = """
import sys
import numpy as np
import OpenImageIO as oiio
*paths, written, output = sys.argv[1:]
for path in paths:
    image = oiio.ImageInput.open(path)
    codes = image.read_image(0, 0, 0, 3, "uint8")
    image.close()
if written == "jpeg-values":
    pixels = (codes.astype(np.float32) / 255.0).astype(np.float16)
else:  # the pixels hdrio wrote, as half
    pixels = np.load(written)
spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 3, "half")
spec.attribute("compression", "zip")
out = oiio.ImageOutput.create(output)
out.open(output, spec)
out.write_image(pixels)
out.close()
"""


def floor_command(paths, written: str | Path, output: str | Path) -> list[str]:
    """The I/O floor as a process: decode ``paths`` (JPEGs), write one half EXR to
    ``output`` of the pixels saved in ``written`` (a ``.npy``), or of the last JPEG's
    values with ``written`` ``"jpeg-values"``."""
    return [sys.executable, "-c", _FLOOR, *map(str, paths), str(written), str(output)]


def hdrio_command() -> list[str]:
    """``hdrio`` as installed beside this interpreter (the console script users type)."""
    script = Path(sys.executable).parent / "hdrio"
    return [str(script)] if script.exists() else [sys.executable, "-m", "hdrio"]


def timed(argv: list[str], env: dict[str, str] | None = None, cores: int = 0,
          cwd: str | Path | None = None) -> dict:
    """Run ``argv`` once, on the first ``cores`` CPUs when given (affinity set before
    the command starts, so hdrio sizes its threads to it as under ``taskset``), in
    ``cwd`` when given: ``{"seconds", "peak_mb", "cpu_seconds", "output"}``.

    A small Python process starts the command and reads its resources from the OS
    (``getrusage`` of its children: peak resident memory, user + system CPU of every
    thread); it is started from this big one by ``posix_spawn``/``vfork``, so the peak is
    the command's own, not a high-water mark inherited through ``fork``. Raises when the
    command fails, with the end of its output.
    """
    completed = subprocess.run([sys.executable, "-c", _MEASURE, str(cores), *argv],
                               capture_output=True, text=True, check=True,
                               env={**os.environ, **(env or {})}, cwd=cwd)
    result = json.loads(completed.stdout.strip().splitlines()[-1])
    if result["returncode"] != 0:
        raise RuntimeError(f"{' '.join(argv[:3])}... failed:\n{result['output'][-1500:]}")
    return result


def baseline_environment(tree: Path, cwd: Path) -> dict[str, str]:
    """The environment in which ``python -m hdrio``, started in ``cwd`` (not a checkout:
    ``python -m`` puts the working directory first on ``sys.path``), runs the ``hdrio``
    package of ``tree`` (a folder holding another commit's ``hdrio/``: ``git archive
    COMMIT hdrio | tar -x -C TREE``); refuses (SystemExit) when it would run another."""
    path = os.pathsep.join([str(tree.resolve()), os.environ.get("PYTHONPATH", "")])
    env = {"PYTHONPATH": path.rstrip(os.pathsep)}
    found = subprocess.run([sys.executable, "-c", "import hdrio; print(hdrio.__file__)"],
                           capture_output=True, text=True, cwd=cwd, check=True,
                           env={**os.environ, **env}).stdout.strip()
    if not Path(found).resolve().is_relative_to(tree.resolve()):
        raise SystemExit(f"--baseline {tree}: python -m hdrio runs {found}")
    return env


def _median(argv: list[str], repeats: int, env: dict[str, str] | None = None) -> dict:
    runs = [timed(argv, env) for _ in range(repeats)]
    return {"seconds": statistics.median(r["seconds"] for r in runs),
            "peak_mb": max(r["peak_mb"] for r in runs),
            "cpu_seconds": statistics.median(r["cpu_seconds"] for r in runs)}


def run(height: int, width: int, repeats: int, counts: tuple[int, ...] = (5, 7, 9)
        ) -> list[dict]:
    """Rows for ``hdrio merge`` (5, 7, 9 JPEG brackets -> half EXR), the I/O floor of
    each, the 7-bracket merge with a JPEG preview, ``hdrio check`` of the 7-bracket EXR,
    and ``hdrio demo`` cold and warm."""
    hdrio = hdrio_command()
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="hdrio-process-") as folder:
        folder = Path(folder)
        ladder, _ = bracket_stack(height, width, count=max(counts))
        paths = [str(p) for p in write_jpegs(ladder, folder)]
        exposures = [repr(float(t)) for t in ladder.exposures]
        ladder = None
        _median([*hdrio, "merge", *paths[1:8], "--exposures", ",".join(exposures[1:8]),
                 "-o", str(folder / "merge7.exr"), "-q"], 1)
        written = folder / "written.npy"  # what hdrio wrote: the floor writes the same
        np.save(written, read_image(folder / "merge7.exr")[0].astype(np.float16))
        for count in counts:
            first = (len(paths) - count) // 2
            chosen = slice(first, first + count)
            output = folder / f"merge{count}.exr"
            floor = _median(floor_command(paths[chosen], written, folder / "floor.exr"),
                            repeats)
            merge = _median([*hdrio, "merge", *paths[chosen], "--exposures",
                             ",".join(exposures[chosen]), "-o", str(output), "-q"], repeats)
            rows.append({"row": "process", "method": f"I/O floor process, {count} JPEGs "
                         "(decode + write hdrio's pixels as half EXR)",
                         "seconds": floor["seconds"], "cpu_seconds": floor["cpu_seconds"],
                         "process_peak_mb": floor["peak_mb"], "floor_of": count})
            rows.append({"row": "process", "method": f"hdrio merge, {count} JPEGs -> half "
                         "EXR", "seconds": merge["seconds"], "cpu_seconds": merge["cpu_seconds"],
                         "process_peak_mb": merge["peak_mb"], "merge_of": count})
        # The README's commands write a tone-mapped preview too (a 24 MP one took 3.0-4.4 s
        # and doubled the peak until its NumPy steps went band by band: docs/speed.md).
        preview = _median([*hdrio, "merge", *paths[1:8], "--exposures", ",".join(
            exposures[1:8]), "-o", str(folder / "preview7.exr"), "--preview",
            str(folder / "preview7.jpg"), "-q"], repeats)
        rows.append({"row": "process", "method": "hdrio merge, 7 JPEGs -> half EXR and a "
                     "JPEG preview", "seconds": preview["seconds"],
                     "cpu_seconds": preview["cpu_seconds"],
                     "process_peak_mb": preview["peak_mb"], "preview_of": 7})
        jpeg_floor = _median(floor_command(paths[1:8], "jpeg-values", folder / "floor.exr"),
                             repeats)
        rows.append({"row": "process", "method": "older floor, 7 JPEGs (writes the JPEG "
                     "values, not hdrio's pixels)", "seconds": jpeg_floor["seconds"],
                     "cpu_seconds": jpeg_floor["cpu_seconds"],
                     "process_peak_mb": jpeg_floor["peak_mb"]})
        check = _median([*hdrio, "check", str(folder / "merge7.exr")], repeats)
        rows.append({"row": "process", "method": f"hdrio check of the {width}x{height} half "
                     "EXR", "seconds": check["seconds"], "cpu_seconds": check["cpu_seconds"],
                     "process_peak_mb": check["peak_mb"], "check": True})
        rows += demo_rows(hdrio, folder)
    return rows


def demo_rows(hdrio: list[str], folder: Path) -> list[dict]:
    """``hdrio demo`` with an empty kernel cache (first run after install), then warm."""
    cache = folder / "numba-cache"
    cache.mkdir()
    env = {"NUMBA_CACHE_DIR": str(cache)}
    cold = timed([*hdrio, "demo", "-o", str(folder / "demo"), "-q"], env)
    shutil.rmtree(folder / "demo")
    warm = timed([*hdrio, "demo", "-o", str(folder / "demo"), "-q"], env)
    return [{"row": "process", "method": "hdrio demo, empty kernel cache (first run)",
             "seconds": cold["seconds"], "cpu_seconds": cold["cpu_seconds"],
             "process_peak_mb": cold["peak_mb"], "demo": "cold"},
            {"row": "process", "method": "hdrio demo, cache filled (every later run)",
             "seconds": warm["seconds"], "cpu_seconds": warm["cpu_seconds"],
             "process_peak_mb": warm["peak_mb"], "demo": "warm"}]


def ratios(rows: list[dict]) -> dict[str, float | None]:
    """Acceptance ratios of issue #16, each from rows of this run."""
    def pick(key: str, value: object) -> dict | None:
        return next((row for row in rows if row.get(key) == value), None)

    result: dict[str, float | None] = {}
    merge7, floor7 = pick("merge_of", 7), pick("floor_of", 7)
    if merge7 and floor7:
        result["process: hdrio merge 7 JPEGs / I/O floor process"] = (
            merge7["seconds"] / floor7["seconds"])
        result["process: the same in CPU seconds (user + system)"] = (
            merge7["cpu_seconds"] / floor7["cpu_seconds"])
    previewed = pick("preview_of", 7)
    if merge7 and previewed:
        result["process: hdrio merge 7 JPEGs with a preview / without"] = (
            previewed["seconds"] / merge7["seconds"])
        result["process: the same in peak MB"] = (
            previewed["process_peak_mb"] / merge7["process_peak_mb"])
    peaks = [row["process_peak_mb"] for row in rows if "merge_of" in row]
    if len(peaks) > 1:
        result["process: peak MB, largest / smallest over 5..9 brackets"] = (
            max(peaks) / min(peaks))
    cold, warm = pick("demo", "cold"), pick("demo", "warm")
    if cold and warm:
        result["process: hdrio demo, empty cache / warm"] = cold["seconds"] / warm["seconds"]
    return result
