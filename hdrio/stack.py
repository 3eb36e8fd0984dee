"""``ExposureStack``: bracket code values, their exposures and where each came from."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hdrio.errors import InputError

MIN_EXPOSURE_STEP = 0.01
"""Exposures closer than this (relative) are the same exposure. Cameras step exposure in
thirds of a stop; frames closer than 1 % are repeats, as a bracket capped by the camera's
shortest or longest shutter time gives (:func:`repeated_exposures`)."""


@dataclass(frozen=True)
class ExposureStack:
    """A validated set of brackets of one scene, sorted by increasing exposure.

    Attributes
    ----------
    codes
        Stored code values, shape ``(P, H, W, C)``, dtype ``uint8`` or ``uint16``; never
        colour-converted on read.
    exposures
        Relative exposure of each bracket, shape ``(P,)``: seconds of exposure time, or
        ``t * ISO/100 / N**2`` when aperture or ISO vary across the set (see
        :mod:`hdrio.io.exposure`).
    files
        Source of each bracket (a path, or a label for synthetic stacks).
    exposure_sources
        How each exposure was found: ``explicit``, ``sidecar``, ``exif`` or ``filename``.
    code_max
        Largest code value of the encoding (255 for 8-bit, 65535 for 16-bit): the
        saturation level.
    dropped
        ``(file, reason)`` of brackets given but not kept (:mod:`hdrio.skips`).
    kinds
        Per bracket, what its code values were found to be when read: ``"dark"``,
        ``"bright"``, ``"covers"`` (every one well exposed), ``"mixed"``, or ``""`` when
        not looked at (:func:`hdrio.skips.classify`).
    """

    codes: np.ndarray
    exposures: np.ndarray
    files: tuple[str, ...]
    exposure_sources: tuple[str, ...]
    code_max: int
    metadata: tuple[dict, ...] = field(default_factory=tuple)
    dropped: tuple[tuple[str, str], ...] = ()
    kinds: tuple[str, ...] = ()
    channel_gains: np.ndarray | None = None
    """``(P, C)`` transmission of each bracket per channel relative to its exposure (an
    ND filter's colour cast, :mod:`hdrio.merge.nd`), or ``None``: 1 everywhere."""

    def __post_init__(self) -> None:
        validate_stack(self)

    @classmethod
    def from_arrays(
        cls,
        codes: np.ndarray,
        exposures,
        files=None,
        code_max: int | None = None,
        exposure_sources=None,
        metadata=None,
        dropped=(),
        kinds=None,
    ) -> ExposureStack:
        """Build a stack from arrays in any order; it is sorted by exposure."""
        codes = np.asanyarray(codes)  # keeps a staged np.memmap one
        if codes.ndim == 3:
            codes = codes[..., np.newaxis]
        exposures = np.asarray(exposures, dtype=np.float64).reshape(-1)
        count = codes.shape[0]
        files = tuple(files) if files is not None else tuple(f"bracket{j}" for j in range(count))
        sources = (
            tuple(exposure_sources) if exposure_sources is not None else ("explicit",) * count
        )
        metadata = tuple(metadata) if metadata is not None else tuple({} for _ in range(count))
        kinds = tuple(kinds) if kinds is not None else ("",) * count
        if code_max is None:
            code_max = int(np.iinfo(codes.dtype).max) if codes.dtype.kind == "u" else 255
        if not (len(files) == len(sources) == len(metadata) == count == exposures.size):
            raise ValueError(
                f"{count} images but {exposures.size} exposures, {len(files)} file names"
            )
        order = np.argsort(exposures, kind="stable")
        in_order = bool(np.all(order == np.arange(count)))
        return cls(
            codes=codes if in_order else codes[order],  # no copy when already sorted
            exposures=exposures[order],
            files=tuple(files[j] for j in order),
            exposure_sources=tuple(sources[j] for j in order),
            code_max=int(code_max),
            metadata=tuple(metadata[j] for j in order),
            dropped=tuple(dropped),
            kinds=tuple(kinds[j] for j in order),
        )

    @property
    def count(self) -> int:
        return int(self.codes.shape[0])

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(height, width, channels)`` of every bracket."""
        return tuple(int(n) for n in self.codes.shape[1:])  # type: ignore[return-value]

    @property
    def channel_exposures(self) -> np.ndarray:
        """What the merge divides by: ``exposures`` ``(P,)``, or ``(P, C)`` times
        ``channel_gains`` when they are set."""
        if self.channel_gains is None:
            return self.exposures
        return self.exposures[:, None] * self.channel_gains

    @property
    def log_exposures(self) -> np.ndarray:
        return np.log(self.exposures)


def first_too_close(exposures: np.ndarray, given=None) -> int | None:
    """The first ``j`` whose next exposure is not :data:`MIN_EXPOSURE_STEP` longer (the
    brackets are in exposure order), or ``None``; ``given``: exposures ``(P,)`` by which
    neighbours that are the same exposure (:func:`repeated_exposures`) need not be
    ordered (a repeat's estimate from the data may fall either side of its twin's)."""
    close = same_as_before(exposures)
    if given is not None:
        close &= ~same_as_before(given)
    close = np.flatnonzero(close)
    return int(close[0]) if close.size else None


def same_exposure(first: float, second: float) -> bool:
    """Whether two exposures, in any order, are one: within :data:`MIN_EXPOSURE_STEP` of
    the longer (:func:`same_as_before` for a sorted array)."""
    return abs(first - second) <= MIN_EXPOSURE_STEP * max(first, second)


def same_as_before(exposures) -> np.ndarray:
    """``(P - 1,)``: whether each bracket after the first has the same exposure as the
    one before it (sorted exposures ``(P,)``, within :data:`MIN_EXPOSURE_STEP`), or is
    shorter."""
    exposures = np.asarray(exposures, np.float64)
    return exposures[1:] < exposures[:-1] * (1.0 + MIN_EXPOSURE_STEP)


def repeated_exposures(exposures) -> list[tuple[int, ...]]:
    """The groups (two brackets or more, indices) of sorted ``exposures`` ``(P,)`` that
    are the same exposure: each neighbour within :data:`MIN_EXPOSURE_STEP` of the one
    before it. A camera capped at its shortest or longest shutter time repeats it; the
    frames are merged as observations of one exposure."""
    exposures = np.asarray(exposures, np.float64)
    groups, current = [], [0]
    for j, same in enumerate(same_as_before(exposures), start=1):
        if same:
            current.append(j)
            continue
        if len(current) > 1:
            groups.append(tuple(current))
        current = [j]
    if len(current) > 1:
        groups.append(tuple(current))
    return groups


def distinct_exposures(exposures) -> int:
    """How many different exposures sorted ``exposures`` holds (repeats counted once)."""
    exposures = np.asarray(exposures, np.float64)
    return int(exposures.size - np.count_nonzero(same_as_before(exposures)))


def validate_stack(stack: ExposureStack) -> None:
    """Raise :class:`InputError` naming the file at fault if the stack is unusable."""
    codes, exposures, files = stack.codes, stack.exposures, stack.files
    if codes.ndim != 4:
        raise ValueError(f"codes must have shape (P, H, W, C); got {codes.shape}")
    if codes.dtype.kind not in "ui":
        raise InputError(files[0], f"code values must be integers, got {codes.dtype}")
    if len(files) + len(stack.dropped) < 2:
        name = files[0] if files else "<no input>"
        raise InputError(name, "at least 2 bracketed exposures are needed; got 1")
    for name, value in zip(files, exposures):
        if not np.isfinite(value) or value <= 0:
            raise InputError(name, f"exposure must be a positive number, got {value!r}")
    # Sorted: a repeat of an exposure (within 1 %) is allowed, a shorter one after a
    # longer one is not (a caller's replace() that broke the order).
    behind = np.flatnonzero(exposures[1:] < exposures[:-1] * (1.0 - MIN_EXPOSURE_STEP))
    if behind.size:
        j = int(behind[0])
        raise InputError(files[j + 1], f"exposure ({exposures[j + 1]:g}) shorter than "
                                       f"{files[j]}'s ({exposures[j]:g}), before which it "
                                       "is sorted")
    if codes.dtype.kind == "u" and np.iinfo(codes.dtype).max <= stack.code_max:
        return  # every value fits: no pass over the codes needed
    if codes.min() < 0 or codes.max() > stack.code_max:
        raise InputError(files[0], f"code values outside 0..{stack.code_max}")


def exposure_columns(exposures) -> np.ndarray:
    """Exposures ``(P,)`` or per channel ``(P, C)`` (:attr:`ExposureStack.channel_exposures`)
    as float64 ``(P, 1)`` or ``(P, C)``, to broadcast against per-channel tables."""
    exposures = np.asarray(exposures, dtype=np.float64)
    return exposures[:, None] if exposures.ndim == 1 else exposures


def some_channel(codes: np.ndarray, test, values) -> np.ndarray:
    """``(...)`` bool: ``test(codes[..., c], values[c])`` holds for some channel ``c`` of
    ``codes`` ``(..., C)`` (e.g. ``np.greater_equal`` and the limits). Channel by channel:
    NumPy's ``any(..., axis=-1)`` over three channels took 8x as long (0.50 s against
    0.06 s on a 24 MP bracket)."""
    result = test(codes[..., 0], values[0])
    for c in range(1, codes.shape[-1]):
        result |= test(codes[..., c], values[c])
    return result


def every_channel(codes: np.ndarray, test, values) -> np.ndarray:
    """``(...)`` bool: ``test(codes[..., c], values[c])`` holds for every channel ``c``
    (:func:`some_channel`'s counterpart)."""
    result = test(codes[..., 0], values[0])
    for c in range(1, codes.shape[-1]):
        result &= test(codes[..., c], values[c])
    return result
