"""Skipping the work a scene does not need, and saying what was skipped.

Six skips, each on by default, each reported in ``hdrio merge``'s summary, each with a
row in ``benchmarks/speed`` (section ``skips``) and a test that it leaves the result
unchanged, or within a stated tolerance:

``brackets``
    A bracket with no well-exposed code value (every code below 5 % of the range: too
    dark; or above 95 %: blown out) adds nothing a neighbour does not, and neither does
    anything beyond it: a shorter exposure than an all-dark bracket is darker still, a
    longer one than an all-bright bracket brighter still. Brackets are decoded from the
    middle of the ladder outwards, so those beyond are dropped *without being decoded*.
``response``
    A saved response (``--response-from``: an EXR written by hdrio) replaces the solve.
``covered``
    When one bracket alone has every code value between 25 % and 95 % of the range, it
    already covers the scene: the merge reduces to that bracket's estimate (with a saved
    response, the other brackets are not even decoded). The result differs from the full
    merge by the noise and quantisation the other brackets would have averaged out
    (``tests/test_skips.py`` states the bounds).
``channels``
    Channels whose samples are identical (greyscale stored as RGB) are solved once.
``early-stop``
    The merge kernel never reads the rows of a bracket, or of any longer one, once a
    shorter bracket's row is saturated everywhere (``hdrio.merge.kernel``).
``warp``
    ``--align auto`` resamples no bracket when a sparse check finds every one within
    0.1 px of the reference (``hdrio.align.quick``, docs/motion.md); turned off, the
    full registration runs and the brackets are always warped.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SKIPS = ("brackets", "response", "covered", "channels", "early-stop", "warp")

WELL_EXPOSED = (0.05, 0.95)
"""Code values strictly inside these fractions of the range are well exposed."""

COVERING = (0.25, 0.95)
"""A bracket covers the scene when all its code values are strictly inside these
fractions: above a quarter of the range a code step is under 3.5 % of radiance for a
gamma-2.2 camera, so one bracket alone is nearly as good as the merge (docs/speed.md)."""


def srgb_decoded(v: np.ndarray | float) -> np.ndarray:
    """sRGB's decoding (IEC 61966-2-1) of ``v`` on [0, 1]: linear light on [0, 1]."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def well_exposed_codes(code_max: int, fractions: tuple[float, float] = WELL_EXPOSED,
                       linear: np.ndarray | None = None) -> tuple[int, int]:
    """``(low, high)``: the code values strictly inside ``fractions`` of the range are
    ``low .. high`` inclusive.

    ``linear``, ``(C, levels)``: the response's ``f^-1`` per channel (at any scale, a
    bracket's ``f^-1 / dt`` too). For codes deeper than 8 bits ``low`` then reaches down
    as far in light below ``high`` as the fractions reach on an sRGB camera's codes
    (5 % of an sRGB range is 7.8 stops under its 95 %, 2 % is 9.2), where that is
    lower: on a linear 16-bit ladder 5 % of the range is only 4.3 stops under 95 %, and
    neighbours 2 EV apart were well exposed together over 2.3 stops (registration
    refused or misplaced them, docs/motion.md). Eight-bit codes keep their fractions: a
    code step is too coarse a share of the light below them."""
    low_fraction, high_fraction = fractions
    low = int(np.floor(low_fraction * code_max)) + 1
    high = int(np.ceil(high_fraction * code_max)) - 1
    if linear is None or code_max <= 255:
        return low, high
    light = np.asarray(linear, dtype=np.float64)[:, :code_max + 1]
    floor = light[:, high] * float(srgb_decoded(low_fraction) / srgb_decoded(high_fraction))
    reach = max(int(np.argmax(row >= level)) for row, level in zip(light, floor))
    return min(low, max(1, reach)), high


def code_range(codes: np.ndarray) -> tuple[int, int]:
    """Smallest and largest value of ``codes`` (any shape).

    NumPy's reductions (10 ms for a 24 MP bracket, just decoded and in cache): a numba
    kernel made it 8 ms faster and cost two seconds of compiling on a first run, while
    the reading threads waited for it."""
    return int(codes.min()), int(codes.max())


def classify(codes: np.ndarray, code_max: int) -> str:
    """``"dark"`` or ``"bright"`` (no code well exposed), ``"covers"`` (every code inside
    :data:`COVERING`) or ``"mixed"``."""
    return classify_range(*code_range(codes), code_max)


def classify_range(low: int, high: int, code_max: int) -> str:
    """:func:`classify` of a bracket whose codes span ``low .. high``."""
    well_low, well_high = well_exposed_codes(code_max)
    if high < well_low:
        return "dark"
    if low > well_high:
        return "bright"
    cover_low, cover_high = well_exposed_codes(code_max, COVERING)
    if low >= cover_low and high <= cover_high:
        return "covers"
    return "mixed"


@dataclass
class SkipReport:
    """What was skipped, for the summary (seconds saved are not known, only the work)."""

    dropped: list[tuple[str, str]] = field(default_factory=list)
    """``(file, reason)`` of every bracket dropped, decoded or not."""
    covering: str | None = None
    """The bracket that alone covered the scene's range (the merge used only it)."""
    response_from: str | None = None
    """Where a saved response came from (the solve was skipped)."""
    channels_solved: int | None = None
    """Distinct channels solved (fewer than the channels when some were identical)."""
    early_stop_fraction: float = 0.0
    """Fraction of pixel-brackets the merge kernel never read."""
    warp: bool = False
    """``--align auto`` measured every bracket within 0.1 px and did not resample."""
    highlights: bool = False
    """``--highlights reconstruct`` found no pixel clipped in every bracket: nothing to do
    (reported, not a choice: there is no work to turn back on)."""

    def lines(self, channels: int) -> list[str]:
        said = []
        if self.dropped:
            said.append("dropped " + ", ".join(f"{name} ({why})" for name, why in self.dropped))
        if self.response_from:
            said.append(f"solve (response from {self.response_from})")
        if self.covering:
            said.append(f"merge of the other brackets ({self.covering} covers the range)")
        if self.channels_solved is not None and self.channels_solved < channels:
            said.append(f"{channels - self.channels_solved} of {channels} channel solves "
                        "(identical channels)")
        if self.warp:
            said.append("alignment warp (every bracket within 0.1 px of the reference)")
        if self.highlights:
            said.append("highlight reconstruction (no pixel clipped in every bracket)")
        if self.early_stop_fraction > 0:
            said.append(f"{100 * self.early_stop_fraction:.1f} % of the merge "
                        "(rows saturated in a shorter bracket)")
        return said
