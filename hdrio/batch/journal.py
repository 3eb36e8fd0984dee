"""The journal of finished sets: the one place that decides whether a set is done.

A set is done when its record says it was finished with the fingerprint the run asks for
(:mod:`hdrio.batch.fingerprint`) *and* every output it lists is still the file that run
wrote (same size and modification time). Anything else (no record, other settings, other
inputs, an output deleted or replaced) means the set is run again.

Records are one small JSON file per set, in a hidden folder beside the set's first
output: ``<folder>/.hdrio-journal/<first output name>.json``. One file per set, written
atomically by whichever process finished the set (a pool worker, a Dask worker on another
machine, a farm task), needs no lock and no shared append on network storage; a record
is written only after every output is in place, so a run killed at any point leaves each
set either recorded with complete outputs or not recorded.
"""

from __future__ import annotations

import datetime
import json
import os
import socket
from collections.abc import Sequence
from pathlib import Path

import hdrio
from hdrio.io.write import write_text

JOURNAL_FOLDER = ".hdrio-journal"


def record_path(outputs: Sequence[str | Path]) -> Path:
    """Where the record of the set whose outputs are ``outputs`` lives."""
    first = Path(outputs[0])
    return first.parent / JOURNAL_FOLDER / f"{first.name}.json"


def _stamp(path: Path) -> list[int] | None:
    try:
        status = os.stat(path)
    except OSError:
        return None
    return [status.st_size, status.st_mtime_ns]


def is_done(outputs: Sequence[str | Path], fingerprint: str) -> bool:
    """Whether a finished record with ``fingerprint`` covers ``outputs`` as they are now.

    A set without outputs is never done (there is nothing to show for it).
    """
    if not outputs:
        return False
    try:
        record = json.loads(record_path(outputs).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    if not isinstance(record, dict) or record.get("fingerprint") != fingerprint:
        return False
    stamps = record.get("outputs", {})
    return all(str(Path(out).resolve()) in stamps
               and stamps[str(Path(out).resolve())] == _stamp(Path(out)) for out in outputs)


def record_done(outputs: Sequence[str | Path], fingerprint: str,
                files: Sequence[str | Path] = ()) -> Path | None:
    """Record that the set is finished: call after every output is written.

    Returns the record's path, or ``None`` for a set without outputs.
    """
    if not outputs:
        return None
    path = record_path(outputs)
    path.parent.mkdir(parents=True, exist_ok=True)
    record = {"fingerprint": fingerprint,
              "outputs": {str(Path(out).resolve()): _stamp(Path(out)) for out in outputs},
              "files": [str(Path(f).resolve()) for f in files],
              "finished": datetime.datetime.now(datetime.timezone.utc).isoformat(),
              "host": socket.gethostname(), "pid": os.getpid(),
              "hdrio": hdrio.__version__}
    return write_text(path, json.dumps(record, indent=1) + "\n")


def forget(outputs: Sequence[str | Path]) -> None:
    """Remove the set's record (``--force``: the set is not done until run again)."""
    if outputs:
        record_path(outputs).unlink(missing_ok=True)
