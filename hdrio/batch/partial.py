"""Clean up the temporary files of killed writers, and only those.

:mod:`hdrio.io.write` writes every output to a hidden temporary file beside it, then
renames it into place; a process killed mid-write (``kill -9``, power loss) leaves the
temporary file behind. Its name carries the writer's host and process id
(:data:`hdrio.io.write.TEMPORARY_NAME`), so a leftover is *provably* stale when it was
written on this host by a process that no longer exists: nothing can be writing it any
more, and it is hdrio's. Temporary files of live processes, of other hosts (a farm
writing to shared storage: their process ids mean nothing here) and files named in any
other way are left alone.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from hdrio.io.write import temporary_writer, this_writer


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, another user's
        return True
    return True


def stale_partials(folders: Iterable[str | Path]) -> list[Path]:
    """hdrio temporary files in ``folders`` whose writer, on this host, is dead."""
    host, _pid = this_writer()
    stale = []
    for folder in dict.fromkeys(Path(f) for f in folders):
        try:
            entries = list(folder.iterdir())
        except OSError:
            continue
        for path in entries:
            writer = temporary_writer(path)
            if writer is not None and writer[0] == host and not _alive(writer[1]):
                stale.append(path)
    return sorted(stale)


def clean_partials(folders: Iterable[str | Path]) -> list[Path]:
    """Remove :func:`stale_partials` of ``folders``; returns what was removed."""
    removed = []
    for path in stale_partials(folders):
        try:
            path.unlink()
        except FileNotFoundError:
            continue
        removed.append(path)
    return removed
