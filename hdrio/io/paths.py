"""The one place that checks the paths hdrio is given, before any work is done.

Inputs: each must name a readable file (not a folder, not a loop of symbolic links, no
name longer than the file system allows), and no file may be given twice (through
another name, a link or a hard link included). Outputs: a name the file system takes, a
type hdrio writes, in a folder that exists and takes a new file, and never one of the
inputs. Every failure is an :class:`~hdrio.errors.InputError` or
:class:`~hdrio.errors.OutputError` naming the path and the problem in one line.

Output name patterns (``-o '{first_stem}_hdr.exr'``) are filled here too
(:func:`fill_pattern`): only ``{name}`` fields, no Python format syntax.
"""

from __future__ import annotations

import errno
import fnmatch
import glob
import os
import re
import stat
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from hdrio.errors import InputError, OutputError
from hdrio.io.write import NAME_MAX, check_writable

_PROBLEMS = {
    errno.ENOENT: "no such file",
    errno.ELOOP: "a loop of symbolic links (a link that points back to itself); "
                 "fix or remove the link",
    errno.EACCES: "permission denied",
    errno.ENOTDIR: "a part of the path is a file, not a folder",
}


def _problem(error: OSError) -> str:
    return _PROBLEMS.get(error.errno or 0, (error.strerror or str(error)).lower())


def name_too_long(path: str | Path) -> str | None:
    """Why ``path`` cannot exist on a POSIX file system (a part over 255 bytes), or None."""
    for part in Path(path).parts:
        size = len(os.fsencode(part))
        if size > NAME_MAX:
            shown = part if len(part) <= 24 else f"{part[:12]}...{part[-8:]}"
            return (f"file name too long ({shown!r} is {size} bytes; a name holds at most "
                    f"{NAME_MAX})")
    return None


IMAGE = "an image file"
"""What an input is, unless said otherwise (:func:`check_input`)."""


def check_input(path: str | Path, what: str = IMAGE) -> os.stat_result:
    """Check that ``path`` is a readable regular file; its ``stat`` (links followed)."""
    too_long = name_too_long(path)
    if too_long:
        raise InputError(path, too_long)
    try:
        info = os.stat(path)
    except OSError as error:
        hint = _other_case(str(path), literal=True) if error.errno == errno.ENOENT else ""
        raise InputError(path, _problem(error) + hint) from None
    if stat.S_ISDIR(info.st_mode):
        hint = f": name its files (e.g. '{Path(path) / '*.jpg'}')" if what == IMAGE else ""
        raise InputError(path, f"is a folder, not {what}{hint}")
    if not stat.S_ISREG(info.st_mode):
        raise InputError(path, f"is not a regular file (a device or pipe?), not {what}")
    if not os.access(path, os.R_OK):
        raise InputError(path, "permission denied (cannot read it)")
    return info


PATTERN_CHARACTERS = "*?["
"""What makes an input name a shell pattern (:func:`expand_patterns`)."""


def expand_patterns(paths: Iterable[str | Path]) -> list[str | Path]:
    """``paths``, each name that is no file but a shell pattern (``*``, ``?``, ``[...]``)
    replaced by the files it matches, sorted as a shell sorts them: a pattern that
    reached hdrio unexpanded (quoted, Windows' ``cmd``, a script's argument list) reads
    as it would have from a shell. One that matches nothing is an error naming it."""
    expanded: list[str | Path] = []
    for path in paths:
        name = str(path)
        if any(c in name for c in PATTERN_CHARACTERS) and not os.path.lexists(name):
            matches = sorted(glob.glob(name))
            if not matches:
                raise InputError(path, "no such file, and as a pattern it matches none"
                                 + _other_case(name))
            expanded.extend(matches)
        else:
            expanded.append(path)
    return expanded


def _other_case(name: str, literal: bool = False) -> str:
    """A hint for a name that finds no file, as a shell pattern or (``literal``) as it
    is: the files its last part finds in its folder when letter case is ignored (a
    camera's ``IMG_0959.JPG`` for ``*.jpg`` or ``img_0959.jpg``), where that folder is
    no pattern; empty when none does. (Linux and most Unix file systems tell ``.jpg``
    from ``.JPG``; Windows and macOS by default do not.)"""
    folder, base = os.path.split(name)
    if not literal and any(c in folder for c in PATTERN_CHARACTERS):
        return ""
    try:
        names = os.listdir(folder or ".")
    except OSError:
        return ""
    matcher = re.compile(re.escape(base) + r"\Z" if literal else fnmatch.translate(base),
                         re.IGNORECASE)
    found = sorted(entry for entry in names if matcher.match(entry))
    if not found:
        return ""
    if literal:
        return f" ({found[0]} is there: letter case counts in file names here)"
    more = f" and {len(found) - 1} more" if len(found) > 1 else ""
    suggested = _with_suffix_of(base, found[0])
    give = (f"; give {os.path.join(folder, suggested)}"
            if all(fnmatch.fnmatchcase(entry, suggested) for entry in found) else "")
    return f" (letter case counts: ignoring it, it matches {found[0]}{more}{give})"


def _with_suffix_of(pattern: str, name: str) -> str:
    """``pattern`` with its suffix written as ``name``'s where the two differ only in
    letter case (``*.jpg`` and ``IMG_0959.JPG``: ``*.JPG``), else as it is."""
    stem, dot, suffix = pattern.rpartition(".")
    name_suffix = name.rpartition(".")[2]
    if dot and suffix.lower() == name_suffix.lower():
        return f"{stem}.{name_suffix}"
    return pattern


def check_inputs(paths: Sequence[str | Path], what: str = IMAGE) -> list[Path]:
    """:func:`check_input` each path, and refuse a file given twice (under any name)."""
    seen: dict[tuple[int, int], Path] = {}
    checked = []
    for path in map(Path, paths):
        info = check_input(path, what)
        key = (info.st_dev, info.st_ino)
        if key in seen:
            same = "" if str(seen[key]) == str(path) else f" (as {seen[key]})"
            raise InputError(path, f"given twice{same}: give each bracket once")
        seen[key] = path
        checked.append(path)
    return checked


def file_key(path: str | Path) -> tuple[int, int] | str:
    """What identifies the file ``path`` names: its device and inode when it exists
    (links and hard links included), else its resolved name (``..`` and linked folders
    resolved). Two paths name one file exactly when their keys are equal."""
    try:
        info = os.stat(path)
    except OSError:  # missing (or unreachable): the name is all there is
        return os.path.realpath(path)
    return info.st_dev, info.st_ino


def same_file(path: str | Path, other: str | Path) -> bool:
    """Whether two paths name one file (see :func:`file_key`)."""
    return file_key(path) == file_key(other)


def check_not_an_input(path: str | Path, inputs: Iterable[str | Path]) -> None:
    """Refuse an output that is one of ``inputs`` (by name, link or hard link)."""
    path = Path(path)
    for source in inputs:
        if same_file(path, Path(source)):
            also = "" if str(source) == str(path) else f" ({source})"
            raise OutputError(f"{path}: output would overwrite an input{also}; choose "
                              "another name")


def _nearest_existing(folder: Path) -> Path:
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


def check_output(path: str | Path, inputs: Iterable[str | Path] = (),
                 suffixes: Iterable[str] | None = None, writable: bool = True) -> Path:
    """Check an output name before any work; ``suffixes`` (lower case, with the dot)
    limits its type. ``writable``: also create and remove a temp file beside it.

    A missing folder is made when the output is written (:func:`make_folder_for`): then
    the nearest existing folder above it must be a folder that takes new entries.
    """
    path = Path(path)
    too_long = name_too_long(path)
    if too_long:
        raise OutputError(f"{path}: {too_long}")
    if path.is_dir():
        raise OutputError(f"{path}: is a folder, not a file name")
    if suffixes is not None:
        allowed = sorted(set(suffixes))
        if path.suffix.lower() not in allowed:
            raise OutputError(f"{path}: unsupported output type; use {', '.join(allowed)}")
    check_not_an_input(path, inputs)
    if not path.parent.is_dir():
        existing = _nearest_existing(path.parent.absolute())
        if not existing.is_dir():
            raise OutputError(f"{path}: {existing} is a file, not a folder")
        if not os.access(existing, os.W_OK | os.X_OK):
            raise OutputError(f"{path}: cannot make folder {path.parent} in {existing} "
                              "(permission denied)")
        return path
    if writable:
        check_writable(path)
    return path


def make_folder_for(path: str | Path) -> Path:
    """Make ``path``'s folder (and those above it) if missing; returns ``path``."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise OutputError(f"{path}: cannot make folder {path.parent} "
                          f"({_problem(error)})") from None
    return path


def check_outputs(outputs: Iterable[tuple[str | Path, Iterable[str] | None]],
                  inputs: Sequence[str | Path] = ()) -> None:
    """:func:`check_output` each ``(path, suffixes)``; two outputs may not share a file."""
    seen: list[Path] = []
    for path, suffixes in outputs:
        path = check_output(path, inputs, suffixes)
        if any(same_file(path, other) for other in seen):
            raise OutputError(f"{path}: named twice as an output")
        seen.append(path)


_FIELD = re.compile(r"{(\w*)}")


def set_fields(files: Sequence[str | Path], index: int = 1) -> dict[str, str]:
    """Names for the output patterns of one bracket set, ``files`` in capture order
    (or as given): ``{first_stem}``, ``{last_stem}``, ``{index}`` (from 1),
    ``{count}``, ``{folder}`` (the first file's)."""
    first, last = Path(files[0]), Path(files[-1])
    return {"first_stem": first.stem, "last_stem": last.stem, "index": str(index),
            "count": str(len(files)), "folder": str(first.parent)}


def is_pattern(text: str | Path) -> bool:
    """Whether an output name has ``{...}`` fields to fill."""
    return "{" in str(text) or "}" in str(text)


def fill_pattern(text: str | Path, fields: Mapping[str, object]) -> Path:
    """``text`` with each ``{name}`` replaced by ``fields[name]``.

    Only plain names: ``{0}``, ``{a.b}``, ``{a!r}`` or a lone brace are refused, naming
    the fields there are (a name pattern is not Python's ``str.format``). The message
    does not repeat ``text``: the caller names the option that gave it.
    """
    text = str(text)
    known = ", ".join(f"{{{name}}}" for name in fields)

    def field(match: re.Match) -> str:
        name = match.group(1)
        if name not in fields:
            raise OutputError(f"unknown field {{{name}}} in the output name; use {known}")
        return str(fields[name])

    if any(brace in _FIELD.sub("", text) for brace in "{}"):
        raise OutputError(f"a brace that is not part of a field {{name}} in the output "
                          f"name; use {known}")
    return Path(_FIELD.sub(field, text))


# Header attributes that name input files: stored resolved (absolute, links followed), and
# beside each, under the same name plus "Relative", relative to the EXR's own folder, so
# that a moved folder (a shot copied to a farm node) still finds its sources.
SOURCE_ATTRIBUTES = ("hdrio:sourceFiles", "hdrio:alignReference")


def resolved(path: str | Path) -> str:
    """``path`` absolute, with links and ``..`` resolved (as a header stores it)."""
    return str(Path(path).resolve())


def relative_to_output(path: str | Path, output: str | Path) -> str:
    """``path`` relative to the folder of ``output`` (both resolved); ``path`` resolved
    when there is no relative path (another drive)."""
    try:
        return os.path.relpath(resolved(path), Path(output).resolve().parent)
    except ValueError:
        return resolved(path)


def with_relative_sources(attributes: Mapping[str, object], output: str | Path
                          ) -> dict[str, object]:
    """``attributes`` plus ``NAMERelative`` for each of :data:`SOURCE_ATTRIBUTES` present:
    its paths relative to the folder ``output`` is written in (a list stays a list)."""
    extended = dict(attributes)
    for name in SOURCE_ATTRIBUTES:
        value = getattr(attributes.get(name), "value", attributes.get(name))
        if isinstance(value, str) and value:
            extended[f"{name}Relative"] = relative_to_output(value, output)
        elif isinstance(value, list | tuple) and value:
            extended[f"{name}Relative"] = [relative_to_output(v, output) for v in value]
    return extended

