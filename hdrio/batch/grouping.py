"""Split a folder or a long list of images into bracket sets.

A panoramic HDRI shoot is often 6 to 12 positions of 5 to 9 brackets each, all in one
folder. Frames are put in capture order (EXIF ``DateTimeOriginal``, then the sequence
number in the file name, then the name), and a new set starts when

* the series changes: frames whose exposures come from the tutorial's file-name
  convention (``north_1_60.png``) belong to the series named by the rest of the name
  (``north``), and a set never spans two series (three ladders in one folder, named
  ``north_*``, ``east_*``, ``south_*``, are three sets);
* ``size`` frames are already in the set, when a fixed bracket count is given
  (``--group-size``); otherwise
* the capture time jumps: more than ``max_gap_s`` seconds after the previous frame
  *ended* (its start plus its exposure time), as when the tripod head turns; or
* the exposure repeats one already in the current set (within 1 %), other than the
  frame's just before it: a camera's bracket rarely shoots the same exposure twice, so a
  repeat is the next set's pattern beginning. This holds whatever the order inside a
  bracket (auto-exposure bracketing's 0, -2, +2). A repeat right after its twin stays
  (a ladder capped by the shutter, shot in exposure order; a burst): no bracket order
  ends on the exposure the next set starts with.

EXIF times have one-second resolution, so frames of one burst often share a stamp; the
sequence number orders them.
"""

from __future__ import annotations

import datetime
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from hdrio.io.brackets import read_exif
from hdrio.io.exposure import exposure_from_exif, exposure_from_filename
from hdrio.io.paths import set_fields
from hdrio.io.raw import RAW_SUFFIXES
from hdrio.stack import same_exposure

BRACKET_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff"}) | RAW_SUFFIXES
DEFAULT_MAX_GAP_S = 2.0  # a bracket burst leaves at most ~1 s between frames, plus rounding
_DIGITS = re.compile(r"\d+")


@dataclass(frozen=True)
class Frame:
    """One image, as far as grouping needs it (no pixels).

    Attributes
    ----------
    path : Path
    exposure : float or None
        Relative exposure: ``t * ISO/100 / N^2`` (seconds at ISO 100, f/1), the quantity
        compared to find repeats; ``None`` when unknown.
    captured : datetime or None
        EXIF ``DateTimeOriginal`` (one-second resolution).
    sequence : int or None
        The last number in the file name (a camera's frame counter).
    time_s : float or None
        The real exposure time in seconds (what the listing prints).
    series : str
        For exposures read from the file name: the name with its numbers taken out
        (``north_#_#.png``); empty otherwise.
    """

    path: Path
    exposure: float | None
    captured: datetime.datetime | None
    sequence: int | None
    time_s: float | None = None
    series: str = ""


@dataclass(frozen=True)
class BracketSet:
    """Frames of one bracket set, in capture order."""

    frames: tuple[Frame, ...]

    @property
    def files(self) -> list[Path]:
        return [frame.path for frame in self.frames]

    @property
    def times_s(self) -> list[float | None]:
        """Real exposure times in seconds, in capture order (``None`` where unknown)."""
        return [frame.time_s for frame in self.frames]

    def fields(self, index: int) -> dict[str, str]:
        """Names for output patterns: ``{first_stem}``, ``{last_stem}``, ``{index}``,
        ``{count}``, ``{folder}`` (``index`` counts from 1)."""
        return set_fields(self.files, index)


def list_images(folder: str | Path) -> list[Path]:
    """Bracket images (8/16-bit formats and camera RAW) directly in ``folder``, by name."""
    folder = Path(folder)
    return sorted(p for p in folder.iterdir()
                  if p.is_file() and p.suffix.lower() in BRACKET_SUFFIXES
                  and not p.name.startswith("."))


def _parse_time(text: object) -> datetime.datetime | None:
    try:
        return datetime.datetime.strptime(str(text).strip()[:19], "%Y:%m:%d %H:%M:%S")
    except ValueError:
        return None


def read_frame(path: str | Path) -> Frame:
    """A :class:`Frame` from the file's header (no pixels decoded), else its name."""
    path = Path(path)
    exif = read_exif(path)
    reading = exposure_from_exif(exif)
    captured = _parse_time(exif.get("DateTimeOriginal"))
    if reading is not None:
        time_s, f_number, iso = reading
        exposure = time_s * (iso / 100.0 if iso else 1.0) / (f_number**2 if f_number else 1.0)
        numbers = _DIGITS.findall(path.stem)
        return Frame(path, exposure, captured, int(numbers[-1]) if numbers else None, time_s)
    named = exposure_from_filename(path)
    if named is not None:  # the numbers in the name are the exposure, not a counter
        series = _DIGITS.sub("#", path.stem) + path.suffix.lower()
        return Frame(path, named, captured, None, named, series)
    numbers = _DIGITS.findall(path.stem)
    return Frame(path, None, captured, int(numbers[-1]) if numbers else None)


def group_frames(frames: Iterable[Frame], max_gap_s: float = DEFAULT_MAX_GAP_S,
                 size: int | None = None) -> list[BracketSet]:
    """Split ``frames`` into bracket sets (see the module notes for the rules).

    Parameters
    ----------
    frames : iterable of Frame
        In any order.
    max_gap_s : float
        Seconds between the end of one frame and the start of the next that start a new
        set (used only when every frame has a capture time).
    size : int, optional
        A fixed bracket count: every ``size`` frames of a series in capture order are one
        set (the last may be short; see :func:`hdrio.batch.tasks.plan_sets`).

    Returns
    -------
    list of BracketSet
        In capture order: ordered by series, then capture time (when every frame has
        one), sequence number and name (a series named by exposure: shortest first).
    """
    frames = list(frames)
    timed = all(frame.captured is not None for frame in frames)

    def order(frame: Frame):
        sequence = frame.sequence if frame.sequence is not None else -1
        shortest_first = (frame.exposure or 0.0) if frame.series else 0.0
        return (frame.series, frame.captured if timed else 0, sequence, shortest_first,
                frame.path.name)

    sets: list[list[Frame]] = []
    for frame in sorted(frames, key=order):
        current = sets[-1] if sets else None
        if current is None or _starts_new_set(current, frame, timed, max_gap_s, size):
            sets.append([frame])
        else:
            current.append(frame)
    return [BracketSet(tuple(frames_of_set)) for frames_of_set in sets]


def _starts_new_set(current: Sequence[Frame], frame: Frame, timed: bool,
                    max_gap_s: float, size: int | None) -> bool:
    previous = current[-1]
    if frame.series != previous.series:
        return True
    if size is not None:
        return len(current) >= size
    if timed:
        length = previous.time_s if previous.time_s is not None else previous.exposure
        ended = previous.captured + datetime.timedelta(seconds=length or 0.0)
        if (frame.captured - ended).total_seconds() > max_gap_s:
            return True
    if frame.exposure is None:
        return False

    def same(other: Frame) -> bool:
        return other.exposure is not None and same_exposure(frame.exposure, other.exposure)

    # A repeat right after its twin is the same set: a ladder capped by the camera's
    # shutter (shot in exposure order), a burst. No bracket order ends on the exposure
    # the next set starts with.
    return not same(previous) and any(same(other) for other in current)


def group_brackets(paths: Sequence[str | Path], max_gap_s: float = DEFAULT_MAX_GAP_S,
                   size: int | None = None) -> list[BracketSet]:
    """Read each file's header and split ``paths`` into bracket sets
    (:func:`group_frames`)."""
    return group_frames((read_frame(path) for path in paths), max_gap_s, size)


def format_times(times: Sequence[float | None]) -> str:
    """Exposure times as a photographer writes them: ``1/64 1/16 1/4 4 s`` (``?`` unknown).

    >>> format_times([1 / 64, 0.25, 4.0, 1 / 1.6])
    '1/64 1/4 4 1/1.6 s'
    """
    def one(t: float | None) -> str:
        if t is None:
            return "?"
        if t >= 1:
            return f"{t:.4g}"
        return f"1/{1 / t:.4g}"

    return " ".join(one(t) for t in times) + " s"
