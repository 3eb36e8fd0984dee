"""Exposure of each bracket: explicit values, sidecar lists, EXIF, or the file name.

Precedence (first that covers every file wins): values given explicitly; a sidecar list;
EXIF; the tutorial's file-name convention. One source serves the whole set, so a stack
never mixes, say, EXIF times for some frames with file-name times for others.

Sidecar formats
---------------
CSV with a header naming the file column and the exposure column (other columns are
ignored)::

    file,exposure_time_s
    church_1.png,0.5

The columns may go by other common names (:data:`FILE_COLUMNS`, :data:`TIME_COLUMNS`:
``filename,shutter`` too), and the values be separated by semicolons or tabs; with
semicolons, as a spreadsheet set to a decimal comma saves it, ``0,125`` is 0.125 s.

OpenCV's ``list.txt`` (as read by ``loadExposureSeq``): one ``file value`` per line where
the value is the *reciprocal* of the exposure time, ``1/t``; ``#`` starts a comment.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Mapping, Sequence
from fractions import Fraction
from pathlib import Path

from hdrio.errors import InputError

_INTEGER = re.compile(r"\d+")
_SECONDS = re.compile(r"\s*(s|\")$")
"""A unit after a time: ``1/8 s``, ``1/8s``, or a camera's seconds mark, ``8"``."""
_EV = re.compile(r"\s*ev$", re.IGNORECASE)
"""The unit of an exposure step: ``-2EV``, ``+2 ev``."""

EV_STEPS = "EV steps"
"""The exposure source of a list given in EV (:func:`explicit_exposures`): relative
exposures, the 0 EV bracket's 1."""


def split_exposures(text: str) -> list[str]:
    """Exposure times as typed in one field, separated by commas, spaces or both
    (``1/8,1,8``, ``1/8 1 8``, ``1/8, 1 8``); a unit standing alone belongs to the time
    before it (``1/8 s, 1 s, 8 s``; ``-2 EV, 0 EV``). Both front ends read a list so:
    ``hdrio merge --exposures`` and Blender's Exposures. A trailing comma leaves an empty
    item, which :func:`parse_exposure` refuses."""
    times: list[str] = []
    for token in re.split(r"[\s,]+", text.strip()):
        if times and (_SECONDS.fullmatch(token) or _EV.fullmatch(token)):
            times[-1] += f" {token}"
        else:
            times.append(token)
    return times


def is_ev(text: str | float) -> bool:
    """Whether ``text`` is an exposure step in EV (``-2EV``, ``+1/3 ev``)."""
    return isinstance(text, str) and _EV.search(text.strip()) is not None


def parse_ev(text: str) -> float:
    """``2^EV`` of ``-2EV``, ``+1/3 EV``, ``0.7ev``: the exposure relative to 0 EV's."""
    number = _EV.sub("", text.strip()).strip()
    try:
        parts = number.split("/")
        if len(parts) > 2:
            raise ValueError
        steps = Fraction(parts[0].strip()) / Fraction(parts[1].strip()) if len(parts) == 2 \
            else Fraction(number)
        if abs(steps) > 64:
            raise ValueError
    except (ValueError, ZeroDivisionError):
        raise ValueError(f"not an exposure step: {text!r} (e.g. -2EV, +1/3EV)") from None
    return 2.0 ** float(steps)


def explicit_exposures(texts: Sequence[str | float]) -> tuple[list[float], bool]:
    """``(exposures, in_ev)`` of a typed list: times in seconds (:func:`parse_exposure`),
    or, when every item is in EV (:func:`parse_ev`), the exposures relative to 0 EV's
    (``-2EV,0EV,+2EV`` is 1/4, 1, 4). A list that mixes the two is refused: which unit
    the bare numbers are in is a guess."""
    ev = in_ev(texts)
    return [parse_ev(str(text)) if ev else parse_exposure(text) for text in texts], ev


def in_ev(texts: Sequence[str | float]) -> bool:
    """Whether a typed list is in EV (every item, :func:`is_ev`) rather than in seconds
    (none); a ``ValueError`` naming two items where it mixes the two."""
    steps = [is_ev(text) for text in texts]
    if any(steps) and not all(steps):
        first = next(text for text, ev in zip(texts, steps) if ev)
        other = next(text for text, ev in zip(texts, steps) if not ev)
        raise ValueError(f"{other!r} beside {first!r}: give every exposure in EV, or every "
                         "one in seconds")
    return bool(steps) and all(steps)


def parse_exposure(text: str | float) -> float:
    """Parse ``"1/60"``, ``"1/3.75"``, ``"0.5"``, ``"30"`` or a number into seconds (a
    positive float); either side of a ``/`` may be a decimal, and a unit may follow
    (``1/60 s``, ``30s``, ``30"``)."""
    try:
        if isinstance(text, int | float):
            value = float(text)
        else:
            parts = _SECONDS.sub("", text.strip()).split("/")
            if len(parts) > 2:
                raise ValueError
            value = float(Fraction(parts[0].strip()) / Fraction(parts[-1].strip())
                          if len(parts) == 2 else Fraction(parts[0].strip()))
    except (ValueError, ZeroDivisionError, OverflowError):
        raise ValueError(f"not an exposure time: {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise ValueError(f"exposure time must be positive and finite: {text!r}")
    return value


def exposure_from_filename(path: str | Path) -> float | None:
    """The tutorial's convention: two integers in the name are numerator and denominator.

    ``church_30_1.jpg`` is 30 s, ``window exp 1 60.jpg`` is 1/60 s. Names with any other
    count of integers (``IMG_2600.jpg``) give ``None``: guessing would be worse than asking.

    >>> exposure_from_filename("window exp 1 60.jpg") == 1 / 60
    True
    >>> exposure_from_filename("IMG_2600.jpg") is None
    True
    """
    numbers = _INTEGER.findall(Path(path).stem)
    if len(numbers) != 2 or int(numbers[1]) == 0 or int(numbers[0]) == 0:
        return None
    return int(numbers[0]) / int(numbers[1])


def read_exposure_table(path: str | Path) -> dict[str, float]:
    """Read a sidecar list into ``{file name: exposure time in seconds}``.

    Names are kept as written (relative paths allowed); lookups match on the name or the
    base name. Raises :class:`InputError` naming the sidecar and the line at fault.
    """
    from hdrio.io.paths import check_input

    path = Path(path)
    check_input(path, "an exposure list")
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except OSError as error:
        raise InputError(path, f"cannot read exposure list ({error.strerror})") from None
    except UnicodeDecodeError as error:
        raise InputError(path, f"not UTF-8 text (byte 0x{error.object[error.start]:02x} at "
                               f"offset {error.start}); save the exposure list as UTF-8"
                         ) from None
    if "\0" in text:
        raise InputError(path, "holds NUL bytes: not a text exposure list")
    # (line number, content) of the lines that carry data: comments and blanks dropped,
    # numbering kept, so errors point at the line a user sees in an editor.
    lines = [(number, line.split("#", 1)[0].strip())
             for number, line in enumerate(text.splitlines(), start=1)]
    lines = [(number, line) for number, line in lines if line]
    if not lines:
        raise InputError(path, "exposure list is empty")
    header = lines[0][1]
    delimiter = next((d for d in (",", ";") if d in header), None)
    if delimiter is None and "\t" in header and _column(_fields(header, "\t"),
                                                     FILE_COLUMNS) is not None:
        delimiter = "\t"  # a tab-separated table; else OpenCV's list, tabs or spaces
    if delimiter is not None:
        return _read_csv_table(path, lines, delimiter)
    return _read_opencv_list(path, lines)


FILE_COLUMNS = ("file", "filename", "file_name", "image", "name", "path")
"""Names of a CSV exposure list's file column, the first found wins (any case)."""
TIME_COLUMNS = ("exposure_time_s", "exposure_time", "exposure", "exposuretime", "shutter",
                "shutter_speed", "time", "seconds")
"""Names of its exposure column, in seconds, the first found wins (any case)."""


def _column(fields: list[str], names: Sequence[str]) -> int | None:
    return next((fields.index(name) for name in names if name in fields), None)


def _fields(header: str, delimiter: str) -> list[str]:
    """A table's column names as compared: any case, spaces as underscores."""
    return [name.strip().lower().replace(" ", "_")
            for name in next(csv.reader([header], delimiter=delimiter))]


def _read_csv_table(path: Path, lines: Sequence[tuple[int, str]], delimiter: str
                    ) -> dict[str, float]:
    header, *rows = lines
    fields = _fields(header[1], delimiter)
    file_column, time_column = _column(fields, FILE_COLUMNS), _column(fields, TIME_COLUMNS)
    if file_column is None or time_column is None:
        raise InputError(path, "CSV exposure list needs a file column ("
                         + ", ".join(FILE_COLUMNS) + ") and an exposure column in seconds ("
                         + ", ".join(TIME_COLUMNS) + f"); its header is {header[1]!r}")
    table: dict[str, float] = {}
    for number, line in rows:
        values = next(csv.reader([line], delimiter=delimiter))
        try:
            name = values[file_column].strip()
            time = values[time_column]
            table[name] = parse_exposure(time.replace(",", ".") if delimiter == ";" else time)
        except (ValueError, IndexError) as error:
            problem = error if isinstance(error, ValueError) else "missing columns"
            raise InputError(path, f"line {number}: {problem}") from None
    return table


def _read_opencv_list(path: Path, lines: Sequence[tuple[int, str]]) -> dict[str, float]:
    table: dict[str, float] = {}
    for number, line in lines:
        parts = line.split()
        if len(parts) != 2:
            raise InputError(path, f"line {number}: expected 'file 1/t', got {line!r}")
        try:
            table[parts[0]] = 1.0 / parse_exposure(parts[1])
        except ValueError as error:
            raise InputError(path, f"line {number}: {error}") from None
    return table


def lookup_in_table(table: Mapping[str, float], file: str | Path) -> float | None:
    """Find ``file`` in a sidecar table by its name as given, else by its base name."""
    file = Path(file)
    for key in (str(file), file.name):
        if key in table:
            return table[key]
    by_name = {Path(name).name: value for name, value in table.items()}
    return by_name.get(file.name)


def exposure_from_exif(exif: Mapping[str, float | None]) -> tuple[float, float, float] | None:
    """``(time_s, f_number, iso)`` from EXIF fields; ``None`` without an exposure time."""
    time = exif.get("ExposureTime")
    if not time or time <= 0:
        return None
    return float(time), float(exif.get("FNumber") or 0.0), float(exif.get("ISO") or 0.0)


def relative_exif_exposures(readings: Sequence[tuple[float, float, float]]) -> list[float]:
    """Exposure times, scaled by ``ISO/100 / N**2`` when aperture or ISO vary in the set.

    With constant aperture and ISO the plain time (seconds) is kept, so values stay
    recognisable; when they vary, each becomes ``t * ISO/100 / N**2`` (all three needed).
    """
    numbers = {reading[1] for reading in readings}
    isos = {reading[2] for reading in readings}
    if len(numbers) == 1 and len(isos) == 1:
        return [reading[0] for reading in readings]
    if any(n <= 0 or iso <= 0 for _, n, iso in readings):
        raise ValueError("aperture or ISO vary across the set, but some frames lack them")
    return [t * iso / 100.0 / n**2 for t, n, iso in readings]
