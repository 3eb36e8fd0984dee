"""Progress lines on stderr: a step log, and a bar that redraws in place on a terminal."""

from __future__ import annotations

import sys
import time


class Progress:
    def __init__(self, quiet: bool = False, stream=None) -> None:
        self.quiet = quiet
        self.stream = stream or sys.stderr
        self.start = time.perf_counter()
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def step(self, message: str) -> None:
        if not self.quiet:
            elapsed = time.perf_counter() - self.start
            print(f"[{elapsed:6.2f} s] {message}", file=self.stream, flush=True)

    def bar(self, done: int, total: int, label: str) -> None:
        if self.quiet or not self.tty:
            return
        width = 30
        filled = int(width * done / max(total, 1))
        end = "\n" if done >= total else ""
        print(f"\r  [{'#' * filled}{'.' * (width - filled)}] {done}/{total} {label[-40:]:40s}",
              end=end, file=self.stream, flush=True)
