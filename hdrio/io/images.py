"""Float images read whole (OpenEXR, Radiance HDR, ...): the chain's EXR inputs, the
checks' and the benchmarks' references, with NaN and infinite values repaired by a stated
rule (:func:`replace_non_finite`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hdrio.errors import InputError, library_message


def replace_non_finite(pixels: np.ndarray, source: str = "image"
                       ) -> tuple[np.ndarray, str | None]:
    """Replace NaN and infinite values by a stated rule; ``(pixels, one-line note)``.

    Per channel: ``+Inf`` becomes the channel's largest finite value and ``-Inf`` its
    smallest (a hot pixel stays the brightest, not infinitely bright); ``NaN`` becomes
    the value of the nearest finite pixel (Euclidean distance), so a NaN row or block
    looks like its surroundings instead of black. The note says how many pixels were
    changed and how, or is ``None`` when every value was finite (then ``pixels`` is
    returned as it is). Raises :class:`InputError` naming ``source`` when a channel has
    no finite value at all.
    """
    pixels = np.asarray(pixels, dtype=np.float32)
    finite = np.isfinite(pixels)
    if finite.all():
        return pixels, None
    from scipy.ndimage import distance_transform_edt

    nan, pos_inf, neg_inf = np.isnan(pixels), np.isposinf(pixels), np.isneginf(pixels)
    out = pixels.copy()
    for c in range(pixels.shape[-1]):
        values = pixels[..., c][finite[..., c]]
        if values.size == 0:
            raise InputError(source, f"channel {c} has no finite value (all NaN or Inf)")
        out[..., c][pos_inf[..., c]] = values.max()
        out[..., c][neg_inf[..., c]] = values.min()
        if nan[..., c].any():
            nearest = distance_transform_edt(nan[..., c], return_distances=False,
                                             return_indices=True)
            out[..., c] = out[..., c][tuple(nearest)]
    count = int(np.count_nonzero(~finite.all(axis=-1)))
    kinds = [(np.count_nonzero(mask.any(axis=-1)), label) for mask, label in
             ((nan, "NaN"), (pos_inf, "+Inf"), (neg_inf, "-Inf"))]
    note = (f"{source}: replaced non-finite values in {count} of {finite[..., 0].size} "
            f"pixels ({', '.join(f'{n} {label}' for n, label in kinds if n)}): NaN by the "
            "nearest finite pixel, +Inf/-Inf by the channel's largest/smallest finite value")
    return out, note


def _channels(image, spec, first: int, stop: int, path: Path) -> np.ndarray:
    """Channels ``first .. stop - 1`` of ``path``, open as OpenImageIO's ``image``,
    ``(H, W, stop - first)`` float32."""
    import OpenImageIO as oiio

    values = image.read_image(0, 0, first, stop, oiio.FLOAT)
    if values is None or image.has_error:
        named = ", ".join(spec.channelnames[first:stop])
        raise InputError(path, f"cannot decode channel {named} "
                               f"({library_message(image.geterror)})")
    return np.asarray(values, dtype=np.float32).reshape(spec.height, spec.width,
                                                        stop - first)


@dataclass(frozen=True)
class Layout:
    """What an image file holds besides the colour and alpha :func:`read_image` reads.

    ``channels``: the first part's other channels by name, each ``(H, W, 1)`` float32
    (an EXR's layers: hdrio's ``motion.Y`` and ``uncertainty.R``, a renderer's ``Z`` and
    ``N.X``...); ``window``: its :class:`hdrio.io.write.Window` (``None`` where its
    pixels are the whole frame); ``pixel_type``: ``"half"`` where every channel is half,
    else ``"float"``; ``parts``: the name of every part (an OpenEXR multi-part file's,
    OpenImageIO's subimages), ``""`` where one has none."""

    channels: dict[str, np.ndarray]
    window: object
    pixel_type: str
    parts: list[str]


def read_layout(path: str | Path) -> Layout:
    """The :class:`Layout` of ``path``, read in one opening of the file."""
    import OpenImageIO as oiio

    from hdrio.io.write import Window

    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise InputError(path, f"cannot read image ({library_message(oiio.geterror)})")
    try:
        spec = image.spec()
        colour = 3 if spec.nchannels >= 3 else 1
        names = list(spec.channelnames)[colour:]
        channels: dict[str, np.ndarray] = {}
        if any(name != "A" for name in names):
            # One read for them all: read one by one, every compressed block of the file
            # was decoded again for each channel.
            rest = _channels(image, spec, colour, spec.nchannels, Path(path))
            channels = {name: rest[..., k:k + 1] for k, name in enumerate(names)
                        if name != "A"}
        formats = {str(f) for f in (spec.channelformats or [spec.format])}
        window = Window.of(spec)
        parts = []
        while image.seek_subimage(len(parts), 0):
            parts.append(image.spec().get_string_attribute("name"))
        return Layout(channels, window, "half" if formats == {"half"} else "float", parts)
    finally:
        image.close()


def read_image(path: str | Path, say=None, alpha: bool = False):
    """Read a float image (OpenEXR, Radiance HDR, ...) as float32 ``(H, W, C)`` RGB.

    Returns the pixels (alpha and extra channels dropped) and the header attributes; with
    ``alpha=True``, the pixels and the ``(H, W, 1)`` alpha channel (``None`` if none)
    instead of the attributes. NaN and infinite values are replaced
    (:func:`replace_non_finite`); ``say(note)``, when given, is called with the one-line
    note saying so.
    """
    import OpenImageIO as oiio

    from hdrio.io.header import read_header

    path = Path(path)
    header = read_header(path)  # names the file when it is missing or unreadable
    image = oiio.ImageInput.open(str(path))
    try:
        spec = image.spec()
        channels = 3 if spec.nchannels >= 3 else 1
        pixels = image.read_image(0, 0, 0, channels, oiio.FLOAT)
        if pixels is None or image.has_error:
            raise InputError(path, f"cannot decode image ({library_message(image.geterror)})")
        names = list(spec.channelnames)
        opacity = None
        if alpha and "A" in names:
            index = names.index("A")
            opacity = _channels(image, spec, index, index + 1, path)
    finally:
        image.close()
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, channels)
    pixels, note = replace_non_finite(pixels, str(path))
    if note and say is not None:
        say(note)
    if alpha:
        return pixels, opacity
    return pixels, {k: v for k, v in header.items() if not k.startswith(".")}
