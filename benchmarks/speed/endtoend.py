"""``hdrio merge`` end to end, JPEG brackets -> half-float EXR, against the I/O floor.

The floor is what any tool must spend here: decoding the same JPEGs and writing the same
EXR (half, ZIP) with the same library, timed in the same run. Peak resident memory is
each whole process's own (``VmHWM``), one fresh process per bracket count.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.speed.scene import bracket_stack
from benchmarks.timing import measure_call
from hdrio.stack import ExposureStack

# VmHWM, not ru_maxrss: Linux carries ru_maxrss over fork and exec, so a child of a big
# benchmark process would report its parent's peak.
_PEAK_PROBE = """
import json, sys, time
from hdrio.job.run import merge_files
paths, exposures, output = sys.argv[1].split(","), sys.argv[2].split(","), sys.argv[3]
start = time.perf_counter()
result = merge_files(paths, output, exposures=exposures)
print(json.dumps({"seconds": time.perf_counter() - start,
                  "peak_mb": next(int(line.split()[1]) / 1024 for line in
                                  open("/proc/self/status") if line.startswith("VmHWM")),
                  "timings": result.timings}))
"""


def write_jpegs(stack: ExposureStack, folder: Path, quality: int = 95) -> list[Path]:
    """The stack's brackets as JPEGs (OpenImageIO, 4:2:0 as cameras write them)."""
    import OpenImageIO as oiio

    paths = []
    for j, codes in enumerate(stack.codes):
        path = folder / f"bracket_{j}.jpg"
        spec = oiio.ImageSpec(codes.shape[1], codes.shape[0], codes.shape[2], "uint8")
        spec.attribute("Compression", f"jpeg:{quality}")
        output = oiio.ImageOutput.create(str(path))
        output.open(str(path), spec)
        output.write_image(codes)
        output.close()
        paths.append(path)
    return paths


def io_floor(paths: list[Path], radiance: np.ndarray, output: Path,
             decoders: int = 1) -> float:
    """Seconds to decode every JPEG and write ``radiance`` as a half ZIP EXR, plainly;
    ``decoders`` files decoded at once (hdrio decodes two)."""
    import OpenImageIO as oiio

    def decode(path: Path) -> None:
        image = oiio.ImageInput.open(str(path))
        image.read_image(0, 0, 0, 3, "uint8")
        image.close()

    start = time.perf_counter()
    with ThreadPoolExecutor(max_workers=decoders) as pool:
        list(pool.map(decode, paths))
    spec = oiio.ImageSpec(radiance.shape[1], radiance.shape[0], 3, "half")
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(str(output))
    out.open(str(output), spec)
    out.write_image(radiance)
    out.close()
    return time.perf_counter() - start


def _peak(paths: list[Path], exposures: list[str], output: Path) -> dict:
    completed = subprocess.run(
        [sys.executable, "-c", _PEAK_PROBE, ",".join(map(str, paths)), ",".join(exposures),
         str(output)], capture_output=True, text=True, check=True,
        env={**os.environ, "PYTHONPATH": str(Path.cwd())})
    return json.loads(completed.stdout.strip().splitlines()[-1])


def run(stack: ExposureStack, repeats: int, counts: tuple[int, ...] = (5, 7, 9)) -> list[dict]:
    from hdrio.job.run import merge_files

    rows: list[dict] = []
    exposures = [repr(float(t)) for t in stack.exposures]
    with tempfile.TemporaryDirectory(prefix="hdrio-speed-") as folder:
        folder = Path(folder)
        paths = write_jpegs(stack, folder)
        hdrio = measure_call(lambda: merge_files(paths, folder / "hdrio.exr",
                                                 exposures=exposures), repeats, warmup=1)
        radiance = hdrio.result.radiance
        timings = hdrio.result.timings
        hdrio.result = None
        floor = measure_call(lambda: io_floor(paths, radiance, folder / "floor.exr"), repeats)
        rows.append({"row": "end to end", "method": "I/O floor (decode JPEGs + write EXR)",
                     "seconds": floor.seconds, "peak_mb": floor.peak_mb})
        floor = measure_call(lambda: io_floor(paths, radiance, folder / "floor.exr", 2),
                             repeats)
        rows.append({"row": "end to end",
                     "method": "I/O floor, two JPEGs decoded at once as hdrio does",
                     "seconds": floor.seconds, "peak_mb": floor.peak_mb})
        rows.append({"row": "end to end", "method": f"hdrio merge ({stack.count} JPEGs)",
                     "end_to_end": "hdrio", "seconds": hdrio.seconds, "peak_mb": hdrio.peak_mb,
                     "steps": {k: round(v, 3) for k, v in timings.items()}})
        radiance = None
        # Peak memory against the bracket count: a 9-bracket ladder of the same scene,
        # ``count`` brackets from its middle, 2 EV apart, one fresh process each.
        ladder, _ = bracket_stack(*stack.codes.shape[1:3], count=max(counts))
        (folder / "ladder").mkdir()
        paths = write_jpegs(ladder, folder / "ladder")
        exposures = [repr(float(t)) for t in ladder.exposures]
        ladder = None
        for count in counts:
            first = (len(paths) - count) // 2
            chosen = slice(first, first + count)
            peak = _peak(paths[chosen], exposures[chosen], folder / f"peak{count}.exr")
            rows.append({"row": "end to end", "method": f"hdrio merge process, {count} JPEGs",
                         "seconds": peak["seconds"], "process_peak_mb": peak["peak_mb"]})
    return rows
