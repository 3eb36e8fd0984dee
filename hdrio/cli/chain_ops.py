"""The chain's inputs and image steps, one registered function each (see
:func:`hdrio.cli.chain_registry.operation`).

To add one, write (and add ``check`` when it can fail on its arguments)::

    @operation("--invert", help="...", example="out.exr --invert -o inverted.exr",
               check=needs_scene_linear)
    def _invert(chain: Chain, _values) -> None:
        image = chain.top()
        image.pixels = some_core_function(image.pixels)
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from hdrio.cli.chain_registry import FLOAT_SUFFIXES, Chain, ChainError, Image, operation
from hdrio.cli.merge_arguments import tonemap_arguments
from hdrio.errors import HdrioError

# ----------------------------------------------------------------------------- inputs

# Attributes that describe the file's layout or the writer, not the pixels: the writer
# sets them anew. Everything else (Copyright, GPS, capDate, ExposureTime, owner,
# screenWindow..., hdrio's provenance) is carried to the outputs, as oiiotool does.
_LAYOUT_PREFIXES = ("oiio:", "openexr:", "compression", "tiff:", "jpeg:", "png:")


def needs_image(chain: Chain, _value: object = None) -> Image:
    """Check: an image is on the stack (a step working on the top image)."""
    return chain.top()


def needs_scene_linear(chain: Chain, _value: object = None) -> Image:
    """Check: the top image is scene-linear (not tone-mapped)."""
    image = chain.top()
    if image.display:
        raise ChainError("the image is display-referred (tone-mapped); do this before "
                         "--tonemap or --ociodisplay")
    return image


def _input_files(chain: Chain, path: Path) -> list[Path]:
    from hdrio.batch.grouping import list_images
    from hdrio.io.paths import name_too_long

    if not name_too_long(path) and path.is_dir():
        files = list_images(path)
        if not files:
            raise ChainError(f"{path}: folder holds no images")
        return files
    if not path.exists() and str(path) not in chain.settings.get("_written", ()):
        raise ChainError(f"{path}: no such file")
    return [path]


def _check_input(chain: Chain, path: Path) -> None:
    files = _input_files(chain, path)
    chain.inputs.extend(files)
    if path.suffix.lower() in FLOAT_SUFFIXES and not path.is_dir():
        from hdrio.io.header import read_header

        header = read_header(path) if path.exists() else {}
        display = header.get("hdrio:units") == "display-referred"
        chain.images.append(Image(np.zeros((1, 1, 3), np.float32), dict(header), str(path),
                                  display=display))
        return
    chain.brackets.extend(files)


@operation("read", "FILE", help="an input file or folder", example="a.jpg", hidden=True,
           convert=lambda values: Path(values[0]), check=_check_input)
def read_input(chain: Chain, path: Path) -> None:
    """A positional input: brackets wait for --merge; float images go on the stack."""
    files = _input_files(chain, path)
    chain.inputs.extend(files)
    if path.is_dir() or path.suffix.lower() not in FLOAT_SUFFIXES:
        chain.brackets.extend(files)
        return
    from hdrio.io.header import read_typed_attributes
    from hdrio.io.images import read_image, read_layout

    layout = read_layout(path)
    if len(layout.parts) > 1:
        named = ", ".join(name or "unnamed" for name in layout.parts)
        chain.note(f"{path}: {len(layout.parts)} parts ({named}); the chain reads and "
                   "writes the first alone")
    pixels, alpha = read_image(path, say=chain.note, alpha=True)
    attributes = {name: value for name, value in read_typed_attributes(path).items()
                  if not name.startswith(_LAYOUT_PREFIXES)}
    image = Image(pixels, attributes, str(path), alpha=alpha, channels=layout.channels,
                  window=layout.window, pixel_type=layout.pixel_type)
    image.display = image.attribute("hdrio:units") == "display-referred"
    image.scale = float(image.attribute("hdrio:exposureScale", 1.0))  # type: ignore[arg-type]
    chain.images.append(image)


# ------------------------------------------------------------------------ image steps


def _stops(values: list[str]) -> float:
    from hdrio.numbers import check_number

    return check_number("--exposure", values[0], minimum=-64, maximum=64, hint="stops")


@operation("--exposure", "STOPS", convert=_stops, check=needs_scene_linear,
           help="scale the scene-linear image by 2^STOPS",
           example="out.exr --exposure -1.5 -o darker.exr")
def _exposure(chain: Chain, stops: float) -> None:
    from hdrio.tools.imageops import apply_exposure

    image = needs_scene_linear(chain)
    image.statistics = None
    image.pixels = apply_exposure(image.pixels, stops)
    image.scale *= 2.0**stops


def _tonemap_check(chain: Chain, value: tuple[str, dict[str, float]]) -> None:
    needs_scene_linear(chain).display = True


@operation("--tonemap", "OPERATOR", optional="NAME=VALUE,...", convert=tonemap_arguments,
           accepts_optional=lambda token: "=" in token and not token.startswith("-"),
           check=_tonemap_check,
           help="tone-map to a display image (sRGB): reinhard-global, reinhard-local, "
                "their -tutorial variants; optional operator parameters",
           example="out.exr --tonemap reinhard-global key=0.18,white=8 -o preview.jpg")
def _tonemap(chain: Chain, value: tuple[str, dict[str, float]]) -> None:
    from hdrio.cms.colour_stage import display_attributes
    from hdrio.cms.spaces import colour_science_name
    from hdrio.radiometry.luminance import DEFAULT_SPACE
    from hdrio.tonemap.preview import render_preview

    name, parameters = value
    image = needs_scene_linear(chain)
    try:
        space = colour_science_name(str(image.attribute("hdrio:colorSpace",
                                                        "lin_rec709_scene")),
                                    chain.settings.get("ocio_config")) or DEFAULT_SPACE
    except HdrioError:  # a space the config does not know: luminance as Rec.709
        space = DEFAULT_SPACE
    unseen = None if image.alpha is None else _unseen_pixels(image.pixels, image.alpha)
    image.pixels = render_preview(image.pixels, name, space, unseen, **parameters)
    image.attributes = display_attributes(image.attributes, f"{name} (sRGB)")
    image.display, image.statistics = True, None


def _unseen_pixels(pixels: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """``(H, W)``: the pixels a preview shows black and leaves out of the key, those
    with no light and alpha 0: hdrio's merge writes them where every bracket was masked
    out (colour at half's smallest positive value, :func:`hdrio.io.write.write_exr`). An
    EXR's colour is premultiplied by its alpha, so alpha 0 with some light is light that
    covers nothing (a flame, a glow, a reflection in glass) and is shown as any other
    pixel (as OpenImageIO's premultiplication keeps it)."""
    from hdrio.io.write import HALF_MIN_POSITIVE

    return (alpha[..., 0] == 0) & np.all(pixels <= HALF_MIN_POSITIVE, axis=-1)


def _size(values: list[str]) -> str:
    if not re.fullmatch(r"\d+(\.\d+)?%|\d+x\d+", values[0]):
        raise ValueError("size must be WIDTHxHEIGHT (0 keeps the aspect) or a percentage")
    return values[0]


@operation("--resize", "SIZE", convert=_size, check=needs_image,
           help="resample to WIDTHxHEIGHT (a 0 keeps the aspect ratio) or to N%",
           example="out.exr --resize 300x0 -o small.exr")
def _resize(chain: Chain, size: str) -> None:
    from hdrio.tools.imageops import resize

    image = chain.top()
    height, width = image.pixels.shape[:2]
    if size.endswith("%"):
        factor = float(size[:-1]) / 100.0
        new_width, new_height = round(width * factor), round(height * factor)
    else:
        new_width, new_height = (int(v) for v in size.split("x"))
        if new_width == 0 and new_height == 0:
            raise ChainError("at most one of width and height may be 0")
        new_width = new_width or round(width * new_height / height)
        new_height = new_height or round(height * new_width / width)
    size_ = max(1, new_width), max(1, new_height)
    if image.window is not None:  # the frame resized with the pixels
        image.window = image.window.scaled(size_[0] / width, size_[1] / height)
    image.pixels = resize(image.pixels, *size_)
    if image.alpha is not None:
        image.alpha = resize(image.alpha, *size_)
    for planes in (image.layers, image.channels):  # masks become fractional, as alpha
        planes.update((name, resize(plane.reshape(*plane.shape[:2], -1), *size_))
                      for name, plane in planes.items())
    image.statistics = None
