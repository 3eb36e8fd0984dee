"""Read bracketed exposures with OpenImageIO, keeping the stored code values."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hdrio.errors import InputError, library_message
from hdrio.io.exposure import (
    EV_STEPS,
    exposure_from_exif,
    exposure_from_filename,
    in_ev,
    lookup_in_table,
    parse_ev,
    parse_exposure,
    read_exposure_table,
    relative_exif_exposures,
)
from hdrio.io.native import quiet_native_stderr, size_thread_pools
from hdrio.io.orientation import UPRIGHT, orientation_of, place, upright_size
from hdrio.io.paths import check_input, check_inputs
from hdrio.io.raw import is_raw, raw_exif, read_raw_set
from hdrio.io.staging import codes_buffer, release, write_rows
from hdrio.parallel import threads
from hdrio.skips import classify_range, code_range
from hdrio.stack import ExposureStack

_CODE_TYPES = {"uint8": (np.uint8, 255), "uint16": (np.uint16, 65535)}


UNREAD_FORMATS = {".heic": "HEIC (HEIF)", ".heif": "HEIF", ".avif": "AVIF"}
"""Formats phones write that this OpenImageIO build reads not (no libheif): named, with
what to export instead."""

_ROWS_PER_READ = 256
PLACEHOLDERS = "data"
"""The exposure source of brackets read with no metadata (``infer_exposures``): their
exposures are placeholders until :func:`hdrio.merge.ladder.infer_exposures`."""


@dataclass(frozen=True)
class BracketHeader:
    """What a bracket's header says, read without decoding its pixels.

    ``height`` and ``width`` are the upright image's, as the bracket is decoded."""

    path: Path
    height: int
    width: int
    channels: int
    code_max: int
    dtype: type
    exif: dict

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.height, self.width, self.channels

    @property
    def orientation(self) -> int:
        """The EXIF orientation reading turns upright (:mod:`hdrio.io.orientation`; 1
        when the pixels are read as stored): ``exif["Orientation"]``, where it says so."""
        return orientation_of(self.exif.get("Orientation"))

    @property
    def stored_size(self) -> tuple[int, int]:
        """``(height, width)`` as the file stores its rows."""
        return upright_size(self.height, self.width, self.orientation)


@contextlib.contextmanager
def _open(path: Path, upright: bool = True) -> Iterator[tuple[object, BracketHeader]]:
    """Open ``path`` with OpenImageIO, check it holds code values, yield its header (of
    the image turned upright by its EXIF orientation, unless ``upright`` is false).

    The libraries' own stderr chatter is silenced for the whole block (decoding included).
    """
    import OpenImageIO as oiio

    check_input(path)
    with quiet_native_stderr():
        # Keep stored values: never let a reader premultiply RGB by a translucent alpha.
        config = oiio.ImageSpec()
        config.attribute("oiio:UnassociatedAlpha", 1)
        image = oiio.ImageInput.open(str(path), config)
        if image is None:
            message = library_message(oiio.geterror)
            if path.suffix.lower() in UNREAD_FORMATS:
                raise InputError(path, f"{UNREAD_FORMATS[path.suffix.lower()]} is not a "
                                       "format hdrio reads: export the brackets as TIFF "
                                       "(16-bit), JPEG or PNG, keeping their EXIF")
            raise InputError(path, f"cannot read image ({message})")
        try:
            spec = image.spec()
            base = str(spec.format)
            if base not in _CODE_TYPES:
                raise InputError(
                    path, f"{base} pixels are not bracket code values; use 8- or 16-bit images"
                )
            dtype, code_max = _CODE_TYPES[base]
            orientation = orientation_of(spec.get_int_attribute("Orientation", UPRIGHT)) \
                if upright else UPRIGHT
            exif = _exif_of(spec)
            if orientation != UPRIGHT:
                exif["Orientation"] = orientation
            header = BracketHeader(path, *upright_size(spec.height, spec.width, orientation),
                                   3 if spec.nchannels >= 3 else 1, code_max, dtype, exif)
            yield image, header
        finally:
            image.close()


def _exif_of(spec) -> dict:
    exif = {
        "ExposureTime": spec.getattribute("ExposureTime"),
        "FNumber": spec.getattribute("FNumber"),
        "ISO": spec.getattribute("Exif:PhotographicSensitivity")
        or spec.getattribute("Exif:ISOSpeedRatings"),
        "DateTimeOriginal": spec.getattribute("Exif:DateTimeOriginal"),
        "Make": spec.getattribute("Make"),
        "Model": spec.getattribute("Model"),
        # The input encoding (hdrio.cms.encoding): ICC description, EXIF ColorSpace.
        "ICCDescription": spec.getattribute("ICCProfile:profile_description"),
        "ExifColorSpace": spec.getattribute("Exif:ColorSpace"),
    }
    return {key: value for key, value in exif.items() if value is not None}


def read_exif(path: str | Path) -> dict:
    """The EXIF fields :func:`read_codes` returns, from the header alone (RAW included)."""
    path = Path(path)
    if is_raw(path):
        return raw_exif(path)
    return read_header(path).exif


def read_header(path: str | Path, upright: bool = True) -> BracketHeader:
    """The header of one bracket (size, channels, code range, EXIF), pixels not decoded;
    its size upright (``upright``: :func:`read_brackets`)."""
    with _open(Path(path), upright) as (_, header):
        return header


def _decode_into(image, header: BracketHeader, out: np.ndarray,
                 decoded: Callable[[int, int], None] | None = None) -> tuple[int, int]:
    """Decode ``image`` into ``out`` ``(H, W, C)`` (upright) a band of stored rows at a
    time (no full copy); ``decoded(top, bottom)`` after each band of an image stored
    upright (a staged bracket gives its pages back there; a turned one's bands cross
    every row). Returns the smallest and largest code, counted band by band."""
    base = str(np.dtype(header.dtype))
    height, width = header.stored_size
    low, high = None, None
    for top in range(0, height, _ROWS_PER_READ):
        bottom = min(height, top + _ROWS_PER_READ)
        rows = image.read_scanlines(0, 0, top, bottom, 0, 0, header.channels, base)
        if rows is None or image.has_error:
            raise InputError(header.path, "cannot decode image "
                             f"({library_message(image.geterror) or 'read failed'})")
        band = np.asarray(rows).reshape(bottom - top, width, header.channels)
        if header.orientation != UPRIGHT or not write_rows(out, top, band):
            place(band, out, top, header.orientation)
        band_low, band_high = code_range(band)
        low = band_low if low is None else min(low, band_low)
        high = band_high if high is None else max(high, band_high)
        if decoded is not None and header.orientation == UPRIGHT:
            decoded(top, bottom)
    return low, high


def read_codes(path: str | Path, upright: bool = True) -> tuple[np.ndarray, int, dict]:
    """Decode one bracket: ``(codes HxWxC, code_max, exif)`` with stored code values,
    turned upright by the file's EXIF orientation unless ``upright`` is false
    (:mod:`hdrio.io.orientation`).

    Only 8- and 16-bit integer encodings are brackets; alpha and extra channels are
    dropped (RGB or a single grey channel are kept). ``exif`` holds ``ExposureTime``,
    ``FNumber``, ``ISO``, ``DateTimeOriginal``, ``ICCDescription`` and ``ExifColorSpace``
    where the file has them, and ``Orientation`` where the pixels were turned upright.
    """
    path = Path(path)
    with _open(path, upright) as (image, header):
        codes = np.empty(header.shape, dtype=header.dtype)
        _decode_into(image, header, codes)
    return codes, header.code_max, header.exif


def read_brackets(
    paths: Sequence[str | Path],
    exposures: Sequence[float | str] | None = None,
    exposures_from: str | Path | None = None,
    progress: Callable[[int, int, str], None] | None = None,
    white_balance: Sequence[float] | None = None,
    skip_brackets: bool = True,
    stop_when_covered: bool = False,
    infer_exposures: bool = False,
    upright: bool = True,
) -> ExposureStack:
    """Read brackets into an :class:`ExposureStack` sorted by increasing exposure.

    Parameters
    ----------
    paths
        Image files (8- or 16-bit JPEG, PNG, TIFF, or anything OpenImageIO reads), or
        camera RAW files (all of them; see :mod:`hdrio.io.raw`).
    exposures
        Exposure times in seconds (``"1/60"`` strings allowed), one per path: wins over
        every other source.
    exposures_from
        A sidecar list (CSV or OpenCV ``list.txt``; see :mod:`hdrio.io.exposure`).
    progress
        Called as ``progress(done, total, path)`` after each file.
    white_balance
        Camera RAW only: multipliers ``(R, G, B)`` for the whole set instead of the first
        file's as-shot ones.
    skip_brackets
        Drop brackets with no well-exposed code value, and those beyond them, without
        decoding the latter (:mod:`hdrio.skips`); they are listed in ``stack.dropped``.
    stop_when_covered
        Stop decoding once a bracket has every code value well exposed, and keep only it
        (for a merge with a saved response: :mod:`hdrio.skips`, ``covered``).
    upright
        Turn each bracket upright by its EXIF orientation (:mod:`hdrio.io.orientation`;
        brackets of one set stored in different orientations then match); false reads
        the pixels as stored, as Blender's image loader does. Camera RAW files are always
        turned (LibRaw's flip).

    Brackets are decoded from the middle of the exposure ladder outwards, as many at a
    time as the process has threads (:func:`hdrio.parallel.threads`), each straight into
    its slot of one array, staged in a temporary file beyond the memory budget
    (:mod:`hdrio.io.staging`).

    Without either, EXIF is used when every file has an exposure time, else the
    file-name convention when every name has one. Raises :class:`InputError` naming the
    file at fault: unreadable, different size, no exposure, duplicate exposure.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise InputError("<no input>", "no images given")
    check_inputs(paths)  # every name, before any header is read
    raw = [is_raw(path) for path in paths]
    if any(raw) and not all(raw):
        raise InputError(paths[raw.index(not raw[0])], "camera RAW and other images cannot "
                                                        "be merged together; use one kind")
    if all(raw):
        return _raw_stack(paths, exposures, exposures_from, progress, white_balance,
                          infer_exposures)
    size_thread_pools()
    # Headers first: sizes and exposures are checked before any pixel is decoded, and
    # each bracket is then decoded straight into its slot of one array, in exposure
    # order (peak memory: the stack plus one band of rows).
    headers = [read_header(path, upright) for path in paths]
    first = headers[0]
    for header in headers[1:]:
        if header.shape != first.shape or header.code_max != first.code_max:
            raise _mismatch(header.path, header.shape, header.code_max, paths[0],
                            first.shape, first.code_max)
    values, source = _resolve_exposures(paths, [h.exif for h in headers], exposures,
                                        exposures_from, infer_exposures)
    if source == PLACEHOLDERS:  # the exposure order is not known before decoding
        skip_brackets = stop_when_covered = False
    order = np.argsort(np.asarray(values, dtype=np.float64), kind="stable")
    count = len(paths)
    codes = codes_buffer((count, *first.shape), first.dtype)
    kinds = [""] * count
    kept = [0, count]  # positions (in exposure order) still kept: kept[0] .. kept[1] - 1
    reasons: dict[int, str] = {}
    found: list[int] = []  # a covering bracket, when stop_when_covered
    lock = threading.Lock()
    done = [0]
    decoded: set[int] = set()

    def decode(position: int) -> None:
        j = order[position]
        with _open(paths[j], upright) as (image, header):
            if header.shape != first.shape or header.code_max != first.code_max:
                raise InputError(paths[j], "changed while being read")
            # each band's pages given back once written: a bracket decoding holds one band
            low, high = _decode_into(image, header, codes[position], lambda top, bottom:
                                     release(codes, position, top, bottom))
        kinds[position] = classify_range(low, high, first.code_max)
        release(codes, position)  # the pages the bands shared
        with lock:
            decoded.add(position)
            if skip_brackets:
                _drop_beyond(position, kinds[position], count, kept, reasons)
            if stop_when_covered and kinds[position] == "covers":
                found.append(position)
            done[0] += 1
            if progress:
                progress(done[0], count, str(paths[j]))

    # From the middle of the ladder outwards, alternating sides (nearest first), on as
    # many threads as the process may use (OpenImageIO releases the GIL while decoding):
    # each side stops where it turns all dark or all bright, and a bracket beyond that is
    # not decoded unless a thread had already started it.
    middle = count // 2
    queue = _outwards(middle, count)
    if stop_when_covered:  # the middle bracket alone first: the likeliest to cover
        decode(queue.pop(0))

    failed: list[BaseException] = []

    def worker() -> None:
        while True:
            with lock:
                position = next((p for p in queue if kept[0] <= p < kept[1]), None)
                if position is None or found or failed:
                    return  # nothing left, a covering bracket found, or a file at fault
                queue.remove(position)
            try:
                decode(position)
            except BaseException as error:
                failed.append(error)
                raise

    workers = max(1, min(threads(), len(queue)))
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="hdrio-read") as pool:
        for future in [pool.submit(worker) for _ in range(workers)]:
            future.result()
    # Of two covering brackets decoded at once, the one nearest the middle, whichever
    # thread found it first.
    covering = min(found, key=_outwards(middle, count).index) if found else None
    if covering is not None:
        kept = [covering, covering + 1]
    for p in decoded:  # decoded ahead by a thread before its side turned dark or bright
        if p in reasons and reasons[p].endswith(": not decoded"):
            reasons[p] = reasons[p].replace(": not decoded", ": decoded ahead, not used")
    names = [str(paths[j]) for j in order]
    dropped = tuple((names[p], reasons.get(p) or
                     f"not needed: {Path(names[covering]).name} covers the range")
                    for p in range(count) if not kept[0] <= p < kept[1])
    chosen = slice(kept[0], kept[1])
    return ExposureStack.from_arrays(
        codes[chosen],  # a view: nothing is copied
        [values[j] for j in order[chosen]],
        files=names[chosen],
        code_max=first.code_max,
        exposure_sources=[source] * (kept[1] - kept[0]),
        metadata=[headers[j].exif for j in order[chosen]],
        dropped=dropped,
        kinds=kinds[chosen],
    )


def _outwards(middle: int, count: int) -> list[int]:
    """Positions ``0 .. count - 1`` from ``middle`` outwards, alternating sides: ``middle,
    middle + 1, middle - 1, middle + 2, ...``."""
    longer, shorter = list(range(middle + 1, count)), list(range(middle - 1, -1, -1))
    interleaved = [middle]
    for k in range(max(len(longer), len(shorter))):
        interleaved += longer[k:k + 1] + shorter[k:k + 1]
    return interleaved


def _drop_beyond(position: int, kind: str, count: int, kept: list[int],
                 reasons: dict[int, str]) -> None:
    """Drop an all-dark bracket and every shorter one, or an all-bright bracket and every
    longer one; never the middle two (``count // 2`` and the next), so two remain."""
    middle = count // 2
    if kind == "dark" and position < middle:
        for p in range(kept[0], position + 1):
            reasons[p] = ("no well-exposed pixel (all dark)" if p == position
                          else "shorter than an all-dark bracket: not decoded")
        kept[0] = max(kept[0], position + 1)
    elif kind == "bright" and position > middle + 1:
        for p in range(position, kept[1]):
            reasons[p] = ("no well-exposed pixel (all bright)" if p == position
                          else "longer than an all-bright bracket: not decoded")
        kept[1] = min(kept[1], position)


def _raw_stack(paths: list[Path], exposures, exposures_from, progress,
               white_balance: Sequence[float] | None, infer: bool) -> ExposureStack:
    """Camera RAW brackets (:mod:`hdrio.io.raw`): linear codes, one white balance."""
    decoded = read_raw_set(paths, white_balance, progress=progress)
    first_codes, code_max, _ = decoded[0]
    for path, (codes, this_max, _) in zip(paths, decoded):
        if codes.shape != first_codes.shape or this_max != code_max:
            raise _mismatch(path, codes.shape, this_max, paths[0], first_codes.shape,
                            code_max)
    exif = [entry[2] for entry in decoded]
    values, source = _resolve_exposures(paths, exif, exposures, exposures_from, infer)
    return ExposureStack.from_arrays(
        np.stack([entry[0] for entry in decoded]), values, files=[str(p) for p in paths],
        code_max=code_max, exposure_sources=[source] * len(paths), metadata=exif)


def _mismatch(path, shape: tuple[int, int, int], code_max: int, first,
              first_shape: tuple[int, int, int], first_max: int) -> InputError:
    """The error for a bracket unlike the first: both described; where it is the first
    turned a quarter (its width the other's height), said so: a file stored in another
    orientation than the set's, which no EXIF ``Orientation`` turned back."""
    turned = (shape[:2] == first_shape[1::-1] and shape[2] == first_shape[2]
              and code_max == first_max)
    return InputError(path, f"is {_describe(shape, code_max)} but {first} is "
                            f"{_describe(first_shape, first_max)}: brackets must match"
                      + ("; it is turned a quarter against it (stored in another "
                         "orientation): turn it to match" if turned else ""))


def _describe(shape: tuple[int, int, int], code_max: int) -> str:
    height, width, channels = shape
    bits = 8 if code_max == 255 else 16
    return f"{width}x{height}, {channels} channel(s), {bits}-bit"


def _resolve_exposures(
    paths: list[Path],
    exif: list[dict],
    explicit: Sequence[float | str] | None,
    sidecar: str | Path | None,
    infer: bool = False,
) -> tuple[list[float], str]:
    """``(exposures, source)`` in the order of ``paths``; with ``infer`` and no source,
    placeholders ``1, 2, 3...`` and :data:`PLACEHOLDERS`."""
    if explicit is not None:
        if len(explicit) != len(paths):
            at_fault = paths[len(explicit)] if len(explicit) < len(paths) else paths[-1]
            raise InputError(
                at_fault, f"{len(explicit)} exposures given for {len(paths)} images"
            )
        try:
            ev = in_ev(explicit)
        except ValueError as error:
            raise InputError(paths[0], f"the exposures given by --exposures: {error}"
                             ) from None
        parse = parse_ev if ev else parse_exposure
        values = []
        for path, text in zip(paths, explicit):  # the item at fault names its file
            try:
                values.append(parse(text))
            except ValueError as error:
                raise InputError(path, str(error)) from None
        return values, EV_STEPS if ev else "explicit"
    if sidecar is not None:
        table = read_exposure_table(sidecar)
        values = []
        for path in paths:
            value = lookup_in_table(table, path)
            if value is None:
                raise InputError(path, f"no exposure for this file in {sidecar}")
            values.append(value)
        return values, "sidecar"
    readings = [exposure_from_exif(entry) for entry in exif]
    if all(readings):
        try:
            return relative_exif_exposures(readings), "exif"  # type: ignore[arg-type]
        except ValueError as error:
            raise InputError(paths[0], str(error)) from None
    from_names = [exposure_from_filename(path) for path in paths]
    if all(value is not None for value in from_names):
        return from_names, "filename"  # type: ignore[return-value]
    if infer:
        return [float(j + 1) for j in range(len(paths))], PLACEHOLDERS
    missing = next(
        (p for p, r, n in zip(paths, readings, from_names) if r is None and n is None),
        next(p for p, r in zip(paths, readings) if r is None),
    )
    raise InputError(
        missing,
        "no exposure time: no EXIF ExposureTime and no 'numerator denominator' in the name; "
        "give --exposures or --exposures-from, or --exposures-from-data to infer them "
        "from the pixels",
    )
