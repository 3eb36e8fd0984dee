"""Brackets shot through a neutral-density filter (``--nd``): the sun with the main set.

``--nd STOPS[:PATTERN]`` says the brackets whose file name matches ``PATTERN`` (shell
wildcards; every bracket when there is none) were shot through a filter of ``STOPS``
stops (an ND 3.0, optical density 3.0, is ``3.0 / log10(2)`` = 9.97 stops; "ND1000"
is 9.97 too). Their exposure is divided by ``2**STOPS`` and they are sorted in with the
others. A real filter is neither exactly its nominal density nor neutral: where
filtered and unfiltered brackets both see a pixel well exposed, the median per channel
of ``g_c(z_nd) - g_c(z) - ln(t_nd / t)`` is the filter's true transmission against the
nominal, per channel (its level and its colour cast). The merge divides by it
(:attr:`hdrio.stack.ExposureStack.channel_gains`), so the sun seen only through the
filter comes out in the unfiltered brackets' colour and level. The response is solved
from the unfiltered brackets only (the filter's cast would bend it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from fnmatch import fnmatchcase
from pathlib import Path

import numpy as np

from hdrio.merge.exposure_check import MAX_PIXELS, MIN_OVERLAP, compared_codes
from hdrio.radiometry.curve import CameraResponse
from hdrio.stack import ExposureStack


@dataclass(frozen=True)
class NDFilter:
    """One ``--nd``: ``stops`` of attenuation on the brackets matching ``pattern``."""

    stops: float
    pattern: str | None = None

    def matches(self, file: str) -> bool:
        """Whether ``file`` is one of the filtered brackets: ``pattern`` (shell wildcards,
        any case, as camera files are often named ``IMG_0961.JPG``) matches its name, its
        name without the suffix (``IMG_0961``) or its path as given."""
        if self.pattern is None:
            return True
        pattern, path = self.pattern.lower(), Path(file)
        return any(fnmatchcase(text.lower(), pattern)
                   for text in (path.name, path.stem, str(file)))


def parse_nd(text: str) -> NDFilter:
    """``STOPS`` or ``STOPS:PATTERN`` -> :class:`NDFilter`; raises ``ValueError``."""
    stops_text, _, pattern = text.partition(":")
    try:
        stops = float(stops_text)
    except ValueError:
        raise ValueError(f"{stops_text!r} is not a number of stops (e.g. 10 for ND 3.0)"
                         ) from None
    if not (math.isfinite(stops) and 0 < stops <= 30):
        raise ValueError(f"{stops_text} stops: give a filter of 0 to 30 stops")
    return NDFilter(stops, pattern or None)


def nd_stops(files: Sequence[str], filters: Sequence[NDFilter]) -> np.ndarray:
    """``(P,)`` stops of filter per bracket (the last ``--nd`` that matches wins).
    Raises ``ValueError`` naming a pattern that matches no bracket."""
    stops = np.zeros(len(files))
    for nd in filters:
        hits = [j for j, name in enumerate(files) if nd.matches(name)]
        if not hits:
            raise ValueError(f"--nd {nd.stops:g}:{nd.pattern}: matches none of the brackets "
                             f"({', '.join(Path(name).name for name in files)})")
        stops[hits] = nd.stops
    return stops


def with_nd(stack: ExposureStack, stops: np.ndarray) -> tuple[ExposureStack, np.ndarray]:
    """The stack with filtered exposures divided by ``2**stops`` and sorted again, and
    the stops in the new order."""
    exposures = stack.exposures * 2.0 ** -stops
    order = np.argsort(exposures, kind="stable")
    sorted_stack = ExposureStack.from_arrays(
        stack.codes, exposures, files=stack.files, code_max=stack.code_max,
        exposure_sources=stack.exposure_sources, metadata=stack.metadata,
        dropped=stack.dropped, kinds=stack.kinds or None)
    return sorted_stack, stops[order]


def stops_of(stack: ExposureStack, named: ExposureStack, stops: np.ndarray
             ) -> np.ndarray:
    """``stops`` (per bracket of ``named``) for the brackets of ``stack``, which may be
    some of them: alignment's re-solve samples the registered brackets alone (a dark
    bracket through the filter is often refused). Matched by file name; by position when
    the names do not tell (``stack`` then has ``named``'s brackets)."""
    by_name = dict(zip(named.files, stops))
    if len(by_name) == len(stops) and all(name in by_name for name in stack.files):
        return np.array([by_name[name] for name in stack.files])
    return stops


def unfiltered(stack: ExposureStack, stops: np.ndarray) -> ExposureStack:
    """The brackets shot without a filter (for the response solve)."""
    keep = np.flatnonzero(stops == 0)
    return ExposureStack.from_arrays(
        stack.codes[keep], stack.exposures[keep], files=[stack.files[j] for j in keep],
        code_max=stack.code_max, exposure_sources=[stack.exposure_sources[j] for j in keep],
        metadata=[stack.metadata[j] for j in keep])


def filter_gains(stack: ExposureStack, response: CameraResponse, stops: np.ndarray
                 ) -> tuple[np.ndarray, dict[float, np.ndarray | None]]:
    """Per bracket and channel, the transmission against the nominal ``2**-stops``:
    ``(P, C)`` (1 for unfiltered brackets), and per filter (by stops) its gains, or
    ``None`` when no filtered bracket shares well-exposed pixels with an unfiltered one
    (then the nominal stops are used, neutral)."""
    count, height, width, channels = stack.codes.shape
    stride = max(1, math.ceil(math.sqrt(height * width / MAX_PIXELS)))
    sample = np.asarray(stack.codes[:, ::stride, ::stride]).reshape(count, -1, channels)
    columns = np.arange(channels)
    low, high = compared_codes(response)
    log_x = response.log_inverse[sample, columns] - np.log(stack.exposures)[:, None, None]
    good = (sample >= low) & (sample <= high) & response.supported[sample, columns]
    gains = np.ones((count, channels))
    found: dict[float, np.ndarray | None] = {}
    for value in sorted(set(stops[stops > 0].tolist())):
        differences: list[list[np.ndarray]] = [[] for _ in range(channels)]
        for j in np.flatnonzero(stops == value):
            for k in np.flatnonzero(stops == 0):
                for c in range(channels):
                    both = good[j, :, c] & good[k, :, c]
                    if np.count_nonzero(both) >= MIN_OVERLAP:
                        differences[c].append(log_x[j, both, c] - log_x[k, both, c])
        if all(differences):
            gain = np.exp([np.median(np.concatenate(d)) for d in differences])
            gains[stops == value] = gain
            found[value] = gain
        else:
            found[value] = None
    return gains, found


@dataclass(frozen=True)
class NDReport:
    """What ``--nd`` did: stops per bracket and each filter's measured transmission."""

    files: tuple[str, ...]
    stops: np.ndarray
    gains: dict[float, np.ndarray | None]

    def lines(self) -> list[str]:
        """One line per filter for the summary."""
        out = []
        for value, gain in self.gains.items():
            names = [Path(f).name for f, s in zip(self.files, self.stops, strict=True)
                     if s == value]
            if gain is None:
                out.append(f"ND {value:g} stops on {', '.join(names)}: no overlap with the "
                           "unfiltered brackets, nominal and neutral")
            else:
                measured = -math.log2(float(np.exp(np.mean(np.log(gain))))) + value
                out.append(f"ND {value:g} stops on {', '.join(names)}: measured "
                           f"{measured:.2f} stops, cast corrected by "
                           f"{', '.join(f'{1 / g:.3f}' for g in gain)} (R, G, B)")
        return out

    def attributes(self) -> dict[str, object]:
        """``hdrio:ndStops`` per bracket (text) and ``hdrio:ndGains`` per filter."""
        attributes: dict[str, object] = {
            "hdrio:ndStops": [f"{Path(f).name} {s:g}" for f, s in
                              zip(self.files, self.stops, strict=True)]}
        attributes["hdrio:ndGains"] = [
            f"{value:g} " + ("nominal" if gain is None else " ".join(f"{g:.6g}" for g in gain))
            for value, gain in self.gains.items()]
        return attributes

