"""Split a folder or a long list of images into bracket sets.

A panoramic HDRI shoot is often 6 to 12 positions of 5 to 9 brackets each, all in one
folder. Frames are put in capture order (EXIF ``DateTimeOriginal``, then the sequence
number in the file name, then the name), and a new set starts when

* the capture time jumps: more than ``max_gap_s`` seconds after the previous frame
  *ended* (its start plus its exposure time), as when the tripod head turns; or
* the exposure repeats one already in the current set (within 1 %): a camera's bracket
  never shoots the same exposure twice, so a repeat is the next set's pattern beginning.

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
from hdrio.io.exposure import exposure_from_exif
from hdrio.io.raw import RAW_SUFFIXES
from hdrio.stack import MIN_EXPOSURE_STEP

BRACKET_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff"}) | RAW_SUFFIXES
DEFAULT_MAX_GAP_S = 2.0  # a bracket burst leaves at most ~1 s between frames, plus rounding
_DIGITS = re.compile(r"\d+")


@dataclass(frozen=True)
class Frame:
    """One image: its exposure (seconds or ``t * ISO/100 / N^2``), capture time, number."""

    path: Path
    exposure: float | None
    captured: datetime.datetime | None
    sequence: int | None


@dataclass(frozen=True)
class BracketSet:
    """Frames of one bracket set, in capture order."""

    frames: tuple[Frame, ...]

    @property
    def files(self) -> list[Path]:
        return [frame.path for frame in self.frames]

    def fields(self, index: int) -> dict[str, str]:
        """Names for output patterns: ``{first_stem}``, ``{last_stem}``, ``{index}``,
        ``{count}``, ``{folder}`` (``index`` counts from 1)."""
        return {"first_stem": self.frames[0].path.stem, "last_stem": self.frames[-1].path.stem,
                "index": str(index), "count": str(len(self.frames)),
                "folder": str(self.frames[0].path.parent)}


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
    """A :class:`Frame` from the file's header (no pixels decoded)."""
    path = Path(path)
    exif = read_exif(path)
    reading = exposure_from_exif(exif)
    exposure = None
    if reading is not None:
        time_s, f_number, iso = reading
        exposure = time_s * (iso / 100.0 if iso else 1.0) / (f_number**2 if f_number else 1.0)
    numbers = _DIGITS.findall(path.stem)
    return Frame(path, exposure, _parse_time(exif.get("DateTimeOriginal")),
                 int(numbers[-1]) if numbers else None)


def group_frames(frames: Iterable[Frame], max_gap_s: float = DEFAULT_MAX_GAP_S
                 ) -> list[BracketSet]:
    """Split ``frames`` into bracket sets (see the module notes for the rules).

    Capture times are used only when every frame has one; otherwise frames keep the
    order of their sequence numbers (then names) and sets split on repeated exposures.
    """
    frames = list(frames)
    timed = all(frame.captured is not None for frame in frames)

    def order(frame: Frame):
        sequence = frame.sequence if frame.sequence is not None else -1
        return (frame.captured if timed else 0, sequence, frame.path.name)

    sets: list[list[Frame]] = []
    for frame in sorted(frames, key=order):
        current = sets[-1] if sets else None
        if current is None or _starts_new_set(current, frame, timed, max_gap_s):
            sets.append([frame])
        else:
            current.append(frame)
    return [BracketSet(tuple(frames_of_set)) for frames_of_set in sets]


def _starts_new_set(current: Sequence[Frame], frame: Frame, timed: bool,
                    max_gap_s: float) -> bool:
    previous = current[-1]
    if timed:
        ended = previous.captured + datetime.timedelta(seconds=previous.exposure or 0.0)
        if (frame.captured - ended).total_seconds() > max_gap_s:
            return True
    if frame.exposure is None:
        return False
    return any(other.exposure is not None
               and abs(frame.exposure - other.exposure)
               <= MIN_EXPOSURE_STEP * max(frame.exposure, other.exposure)
               for other in current)


def group_brackets(paths: Sequence[str | Path], max_gap_s: float = DEFAULT_MAX_GAP_S
                   ) -> list[BracketSet]:
    """Read each file's header and split ``paths`` into bracket sets."""
    return group_frames((read_frame(path) for path in paths), max_gap_s)


def output_is_complete(output: str | Path, sources: Sequence[str | Path]) -> bool:
    """Whether ``output`` already holds the result for ``sources``.

    Outputs are written atomically, so an existing file is whole; an EXR must also name
    exactly these sources in ``hdrio:sourceFiles`` (a set shot again, or regrouped,
    is merged again).
    """
    from hdrio.errors import HdrioError
    from hdrio.io.header import read_header

    output = Path(output)
    if not output.is_file():
        return False
    try:
        header = read_header(output)
    except HdrioError:
        return False
    if output.suffix.lower() != ".exr":
        return True
    recorded = header.get("hdrio:sourceFiles")
    if recorded is None:
        return False
    recorded = [recorded] if isinstance(recorded, str) else list(recorded)
    return ({Path(p).resolve() for p in recorded} == {Path(p).resolve() for p in sources})
