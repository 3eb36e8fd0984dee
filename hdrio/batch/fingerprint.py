"""The fingerprint of a bracket set: what its outputs were made from and how.

Two runs that would write the same outputs have the same fingerprint; anything that can
change an output changes it:

* each input file's identity: its resolved path, size in bytes and modification time in
  nanoseconds (a file shot again, edited or replaced differs; reading the pixels to hash
  them would cost as much as the merge);
* the recipe: every setting of the chain that affects the outputs, as text, in order
  (the front end decides what belongs there; :mod:`hdrio.cli.chain_batch` puts every
  step but the ones that only say how to run, such as ``--threads`` or ``--dask``);
* the identity of files the settings name (a sidecar exposure list, a saved response);
* hdrio's version.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable
from pathlib import Path

import hdrio


def file_identity(path: str | Path) -> list[object]:
    """``[resolved path, size in bytes, modification time in ns]`` of ``path``;
    ``[path, None, None]`` when it cannot be read (a missing file is an identity too)."""
    path = Path(path).resolve()
    try:
        status = os.stat(path)
    except OSError:
        return [str(path), None, None]
    return [str(path), status.st_size, status.st_mtime_ns]


def set_fingerprint(files: Iterable[str | Path], recipe: Iterable[str],
                    named_files: Iterable[str | Path] = ()) -> str:
    """The fingerprint of one set: a SHA-256 hex digest (64 characters).

    Parameters
    ----------
    files : iterable of path
        The set's input frames, in set order.
    recipe : iterable of str
        Every setting that affects the outputs, as text (e.g. the chain's steps).
    named_files : iterable of path
        Files the settings refer to, whose content therefore matters too.
    """
    document = {"hdrio": hdrio.__version__,
                "inputs": [file_identity(path) for path in files],
                "recipe": list(recipe),
                "named_files": [file_identity(path) for path in named_files]}
    text = json.dumps(document, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
