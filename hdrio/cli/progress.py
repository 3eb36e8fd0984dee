"""Progress lines on stderr: a step log, and a bar that redraws in place on a terminal.

With ``HDRIO_PROGRESS_CPU=1`` each step also says the CPU seconds the process has used
since it started, every thread's (``[  1.26 s, CPU   4.80 s] camera response``): how
``python -m benchmarks.cores`` sees where the CPU goes, stage by stage, on many cores.
"""

from __future__ import annotations

import os
import sys
import time


def _process_cpu() -> float:
    times = os.times()
    return times.user + times.system


class Progress:
    def __init__(self, quiet: bool = False, stream=None) -> None:
        self.quiet = quiet
        self.stream = stream or sys.stderr
        self.start = time.perf_counter()
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.cpu = os.environ.get("HDRIO_PROGRESS_CPU", "").strip() not in ("", "0")

    def step(self, message: str) -> None:
        if not self.quiet:
            elapsed = time.perf_counter() - self.start
            cpu = f", CPU {_process_cpu():6.2f} s" if self.cpu else ""
            print(f"[{elapsed:6.2f} s{cpu}] {message}", file=self.stream, flush=True)

    def bar(self, done: int, total: int, label: str) -> None:
        if self.quiet or not self.tty:
            return
        width = 30
        filled = int(width * done / max(total, 1))
        end = "\n" if done >= total else ""
        print(f"\r  [{'#' * filled}{'.' * (width - filled)}] {done}/{total} {label[-40:]:40s}",
              end=end, file=self.stream, flush=True)
