"""Run a :class:`~benchmarks.truth.config.Config`: render, merge with every method, measure."""

from __future__ import annotations

import os
import platform
import statistics
import subprocess
import time
from collections.abc import Callable
from datetime import datetime, timezone
from importlib import metadata

from benchmarks.timing import measure_call
from benchmarks.truth.config import Config
from benchmarks.truth.curves import load_curve
from benchmarks.truth.methods import Method, MethodOutput, select_methods
from benchmarks.truth.metrics import evaluate, regions
from benchmarks.truth.scenes import REPO_ROOT, Scene, builtin_scenes, read_scene
from benchmarks.truth.stacks import Stack, render_stack

Progress = Callable[[str], None]
PACKAGES = ("hdrio", "numpy", "scipy", "colour-science", "colour-hdri", "OpenImageIO",
            "matplotlib", "opencv-python-headless", "opencv-python", "opencv-contrib-python")


def environment() -> dict[str, object]:
    """Versions, CPU, date and git commit, recorded with every run."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    try:
        import cv2

        versions["cv2"] = cv2.__version__
    except ImportError:
        pass
    commit = dirty = None
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, text=True,
                                capture_output=True, check=True).stdout.strip()
        status = subprocess.run(["git", "status", "--porcelain", "hdrio"], cwd=REPO_ROOT,
                                text=True, capture_output=True, check=True).stdout
        dirty = bool(status.strip())
    except (OSError, subprocess.CalledProcessError):
        pass
    cpu_model = platform.processor()
    try:
        with open("/proc/cpuinfo") as info:
            cpu_model = next((line.split(":", 1)[1].strip() for line in info
                              if line.startswith("model name")), cpu_model)
    except OSError:
        pass
    return {
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "python": platform.python_version(), "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
        "cpu_available": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
        else os.cpu_count(),
        "cpu_model": cpu_model, "versions": versions,
        "git_commit": commit, "hdrio_dirty": dirty,
    }


def load_scenes(config: Config) -> dict[str, Scene]:
    """The configuration's scenes by name: ``--scene`` files, else ``openexr_scenes``."""
    if config.scene_paths:
        return {name: read_scene(path, config.width) for name, path in config.scene_paths.items()}
    return {scene.name: scene for scene in builtin_scenes(tuple(config.scene_names), config.width)}


def measure(method: Method, stack: Stack, repeats: int
            ) -> tuple[MethodOutput, list[float], float | None]:
    """Call ``method`` on ``stack`` ``repeats`` times, each under peak-memory sampling.

    Returns
    -------
    output, times, peak_mb
        The last output, every wall time (s), the largest peak (MB, ``None`` off Linux).
    """
    timing = measure_call(lambda: method.run(stack), repeats)
    return timing.result, timing.times, timing.peak_mb


def run(config: Config, progress: Progress | None = None) -> dict[str, object]:
    """Every (stack, method) row, plus the configuration and the environment."""
    say = progress or (lambda message: None)
    started = time.perf_counter()
    methods = select_methods(list(config.methods) if config.methods else None)
    notes = [f"{m.name}: skipped, {m.missing()}" for m in methods if m.missing()]
    methods = [m for m in methods if not m.missing()]
    scenes = load_scenes(config)
    curves = {name: load_curve(name) for name in config.curve_names}
    rows: list[dict[str, object]] = []
    warmed: set[str] = set()
    for index, spec in enumerate(config.stacks, 1):
        scene = scenes[spec.scene]
        stack = render_stack(spec, scene, curves[spec.curve])
        masks = regions(stack.codes, stack.code_max)
        say(f"[{index}/{len(config.stacks)}] {spec.key} {scene.radiance.shape[1]}x"
            f"{scene.radiance.shape[0]}")
        for method in methods:
            if not method.supports(stack):
                continue
            row: dict[str, object] = {
                "stack": spec.key, "group": spec.group, "scene": spec.scene,
                "curve": spec.curve, "frames": spec.frames, "ev": spec.ev, "bits": spec.bits,
                "encoding": spec.encoding, "seed": spec.seed,
                "width": int(scene.radiance.shape[1]), "height": int(scene.radiance.shape[0]),
                "method": method.name, "kind": method.kind,
            }
            try:
                if method.name not in warmed:
                    method.run(stack)  # warm-up: imports, caches, first-touch allocations
                    warmed.add(method.name)
                output, times, peak = measure(method, stack, config.repeats_for(spec))
                row.update(status="ok", time_s=statistics.median(times), times_s=times,
                           peak_mb=peak)
                row.update(evaluate(output, stack, masks))
                if output.saturation is not None:
                    row["saturation"] = output.saturation
                del output
            except Exception as error:  # a peer (or hdrio) failing is a result, not a crash
                row.update(status="error", error=f"{type(error).__name__}: {error}")
            rows.append(row)
            well = row.get("well") or {}
            say(f"    {method.name:24s} {row['status']:5s} median "
                f"{_pct(well.get('median'))} p99 {_pct(well.get('p99'))} "
                f"{row.get('time_s', float('nan')):.2f} s")
    return {
        "config": {"name": config.name, "width": config.width, "repeats": config.repeats,
                   "timed_groups": list(config.timed_groups),
                   "stacks": len(config.stacks), "scene_paths": config.scene_paths,
                   "scenes": {name: scene.source for name, scene in scenes.items()}},
        "environment": environment(),
        "methods": [{"name": m.name, "kind": m.kind, "description": m.description,
                     "bits": list(m.bits), "settings": m.settings} for m in methods],
        "notes": notes,
        "rows": rows,
        "wall_time_s": time.perf_counter() - started,
    }


def _pct(value: object) -> str:
    return f"{100 * value:6.2f} %" if isinstance(value, float) else "     - "
