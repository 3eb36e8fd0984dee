"""Compile hdrio's numba kernels in a background thread (no ``bpy`` here).

hdrio's kernels are compiled on their first call and cached on disk (numba ``cache=True``);
the first Solve, Merge to EXR or Reinhard Local of a new installation would otherwise
freeze Blender's UI for 8-10 s. The extension starts :data:`WARMUP` when it is enabled; the
operators wait for it (in the background) or ask the user to retry (with a UI), and
``__init__.py`` shows its progress.
"""

from __future__ import annotations

import tempfile
import threading
from collections.abc import Callable
from pathlib import Path


def _merge_tiny_stack() -> None:
    """Read, solve, merge and write a 3-bracket 24x32 stack (every kernel of a merge)."""
    from hdrio.io.write import write_image
    from hdrio.job.run import merge_files
    from hdrio.tools.synthetic import demo_scene, render_brackets

    exposures = (1 / 16, 1 / 2, 4.0)
    codes = render_brackets(demo_scene(24, 32), exposures)
    with tempfile.TemporaryDirectory(prefix="hdrio-warmup-") as folder:
        paths = [write_image(Path(folder) / f"b{j}.png", bracket, "uint8")
                 for j, bracket in enumerate(codes)]
        merge_files(paths, Path(folder) / "merged.exr",
                    exposures=[repr(t) for t in exposures])


def _tonemap_tiny_image() -> None:
    """Hdrio's Reinhard operators on a 24x32 image."""
    from hdrio.tonemap import TONEMAP_METHODS
    from hdrio.tools.synthetic import demo_scene

    radiance = demo_scene(24, 32)
    for name in ("reinhard-local", "reinhard-global"):
        TONEMAP_METHODS[name](radiance)


STEPS: tuple[tuple[str, Callable[[], None]], ...] = (
    ("merge", _merge_tiny_stack), ("Reinhard", _tonemap_tiny_image))


class KernelWarmup:
    """Run ``steps`` once, in a daemon thread; thread-safe progress for the UI."""

    def __init__(self, steps: tuple[tuple[str, Callable[[], None]], ...] = STEPS) -> None:
        self.steps = steps
        self.done = 0
        self.error: str = ""
        self._thread: threading.Thread | None = None
        self._finished = threading.Event()

    def start(self) -> None:
        """Start compiling (only the first call does anything)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="hdrio kernel warm-up",
                                            daemon=True)
            self._thread.start()

    def _run(self) -> None:
        try:
            for _, step in self.steps:
                step()
                self.done += 1
        except Exception as error:  # noqa: BLE001 - reported, and the operators still run
            self.error = f"{type(error).__name__}: {error}"
        finally:
            self._finished.set()

    @property
    def finished(self) -> bool:
        return self._finished.is_set()

    @property
    def running(self) -> bool:
        return self._thread is not None and not self.finished

    def wait(self, timeout: float | None = None) -> bool:
        """Block until finished (or ``timeout`` seconds); True when finished."""
        return self._finished.wait(timeout)

    def status(self) -> str:
        """One line for the status bar, e.g. ``hdrio: compiling kernels (1/2: Reinhard)``."""
        if self.error:
            return f"hdrio: kernel warm-up failed ({self.error})"
        if self.finished:
            return "hdrio: kernels ready"
        name = self.steps[min(self.done, len(self.steps) - 1)][0]
        return f"hdrio: compiling kernels ({self.done}/{len(self.steps)}: {name})"


WARMUP = KernelWarmup()
"""The extension's one warm-up (started by ``register()``)."""
