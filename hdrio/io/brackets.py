"""Read bracketed exposures with OpenImageIO, keeping the stored code values."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np

from hdrio.errors import InputError
from hdrio.io.exposure import (
    exposure_from_exif,
    exposure_from_filename,
    lookup_in_table,
    parse_exposure,
    read_exposure_table,
    relative_exif_exposures,
)
from hdrio.io.raw import is_raw, raw_exif, read_raw_set
from hdrio.stack import ExposureStack

_CODE_TYPES = {"uint8": (np.uint8, 255), "uint16": (np.uint16, 65535)}


@contextlib.contextmanager
def _quiet_native_stderr() -> Iterator[None]:
    """Swallow what C libraries (libpng, libjpeg) print on fd 2 while decoding.

    OpenImageIO reports the same problem through ``geterror()``, which we turn into one
    clear line; the library's own chatter would only add noise to it.
    """
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    sys.stderr.flush()
    saved = os.dup(fd)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), fd)
        try:
            yield
        finally:
            os.dup2(saved, fd)
            os.close(saved)


def read_codes(path: str | Path) -> tuple[np.ndarray, int, dict]:
    """Decode one bracket: ``(codes HxWxC, code_max, exif)`` with stored code values.

    Only 8- and 16-bit integer encodings are brackets; alpha and extra channels are
    dropped (RGB or a single grey channel are kept). ``exif`` holds ``ExposureTime``,
    ``FNumber``, ``ISO`` and ``DateTimeOriginal`` where the file has them.
    """
    import OpenImageIO as oiio

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such file")
    with _quiet_native_stderr():
        # Keep stored values: never let a reader premultiply RGB by a translucent alpha.
        config = oiio.ImageSpec()
        config.attribute("oiio:UnassociatedAlpha", 1)
        image = oiio.ImageInput.open(str(path), config)
        if image is None:
            raise InputError(path, f"cannot read image ({_first_line(oiio.geterror())})")
        try:
            spec = image.spec()
            base = str(spec.format)
            if base not in _CODE_TYPES:
                raise InputError(
                    path, f"{base} pixels are not bracket code values; use 8- or 16-bit images"
                )
            dtype, code_max = _CODE_TYPES[base]
            channels = 3 if spec.nchannels >= 3 else 1
            pixels = image.read_image(0, 0, 0, channels, base)
            if pixels is None or image.has_error:
                raise InputError(
                    path, f"cannot decode image ({_first_line(image.geterror()) or 'read failed'})"
                )
            exif = _exif_of(spec)
        finally:
            image.close()
    codes = np.asarray(pixels, dtype=dtype).reshape(spec.height, spec.width, channels)
    return codes, code_max, exif


def _exif_of(spec) -> dict:
    exif = {
        "ExposureTime": spec.getattribute("ExposureTime"),
        "FNumber": spec.getattribute("FNumber"),
        "ISO": spec.getattribute("Exif:PhotographicSensitivity")
        or spec.getattribute("Exif:ISOSpeedRatings"),
        "DateTimeOriginal": spec.getattribute("Exif:DateTimeOriginal"),
    }
    return {key: value for key, value in exif.items() if value is not None}


def read_exif(path: str | Path) -> dict:
    """The EXIF fields :func:`read_codes` returns, from the header alone (RAW included)."""
    import OpenImageIO as oiio

    path = Path(path)
    if is_raw(path):
        return raw_exif(path)
    if not path.is_file():
        raise InputError(path, "no such file")
    with _quiet_native_stderr():
        image = oiio.ImageInput.open(str(path))
        if image is None:
            raise InputError(path, f"cannot read image ({_first_line(oiio.geterror())})")
        try:
            return _exif_of(image.spec())
        finally:
            image.close()


def _first_line(message: str) -> str:
    lines = [line for line in message.strip().splitlines() if line.strip()]
    return lines[0] if lines else ""


def read_brackets(
    paths: Sequence[str | Path],
    exposures: Sequence[float | str] | None = None,
    exposures_from: str | Path | None = None,
    progress: Callable[[int, int, str], None] | None = None,
    white_balance: Sequence[float] | None = None,
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

    Without either, EXIF is used when every file has an exposure time, else the
    file-name convention when every name has one. Raises :class:`InputError` naming the
    file at fault: unreadable, different size, no exposure, duplicate exposure.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise InputError("<no input>", "no images given")
    raw = [is_raw(path) for path in paths]
    if any(raw) and not all(raw):
        raise InputError(paths[raw.index(not raw[0])], "camera RAW and other images cannot "
                                                        "be merged together; use one kind")
    if all(raw):
        decoded = read_raw_set(paths, white_balance, progress=progress)
    else:
        decoded = []
        for done, path in enumerate(paths, start=1):
            decoded.append(read_codes(path))
            if progress:
                progress(done, len(paths), str(path))
    first_codes, code_max, _ = decoded[0]
    for path, (codes, this_max, _) in zip(paths, decoded):
        if codes.shape != first_codes.shape or this_max != code_max:
            raise InputError(
                path,
                f"is {_describe(codes, this_max)} but {paths[0]} is "
                f"{_describe(first_codes, code_max)}: brackets must match",
            )
    exif = [entry[2] for entry in decoded]
    values, source = _resolve_exposures(paths, exif, exposures, exposures_from)
    return ExposureStack.from_arrays(
        np.stack([entry[0] for entry in decoded]),
        values,
        files=[str(p) for p in paths],
        code_max=code_max,
        exposure_sources=[source] * len(paths),
        metadata=exif,
    )


def _describe(codes: np.ndarray, code_max: int) -> str:
    height, width, channels = codes.shape
    bits = 8 if code_max == 255 else 16
    return f"{width}x{height}, {channels} channel(s), {bits}-bit"


def _resolve_exposures(
    paths: list[Path],
    exif: list[dict],
    explicit: Sequence[float | str] | None,
    sidecar: str | Path | None,
) -> tuple[list[float], str]:
    if explicit is not None:
        if len(explicit) != len(paths):
            at_fault = paths[len(explicit)] if len(explicit) < len(paths) else paths[-1]
            raise InputError(
                at_fault, f"{len(explicit)} exposures given for {len(paths)} images"
            )
        values = []
        for path, text in zip(paths, explicit):
            try:
                values.append(parse_exposure(text))
            except ValueError as error:
                raise InputError(path, str(error)) from None
        return values, "explicit"
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
    missing = next(
        (p for p, r, n in zip(paths, readings, from_names) if r is None and n is None),
        next(p for p, r in zip(paths, readings) if r is None),
    )
    raise InputError(
        missing,
        "no exposure time: no EXIF ExposureTime and no 'numerator denominator' in the name; "
        "give --exposures or --exposures-from",
    )
