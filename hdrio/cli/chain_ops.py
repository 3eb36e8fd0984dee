"""The chain's operations, one registered function each (see :func:`chain.operation`).

To add one (a colour operation, say), write::

    @operation("--colorspace", "NAME", help="...", example="--colorspace ACEScg",
               convert=lambda values: values[0])
    def _colorspace(chain: Chain, name: str) -> None:
        image = chain.top()
        image.pixels = some_core_function(image.pixels, name)
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

from hdrio.align import ALIGN_MODES, DEGHOST_MODES
from hdrio.cli.chain import (
    FLOAT_SUFFIXES,
    Chain,
    ChainError,
    Image,
    one_argument,
    operation,
)

_one = one_argument


def _number(values: list[str]) -> float:
    try:
        return float(values[0])
    except ValueError:
        raise ValueError(f"not a number: {values[0]!r}") from None


# ----------------------------------------------------------------------------- inputs


def read_input(chain: Chain, path: Path) -> None:
    """A positional input: brackets wait for --merge; float images go on the stack."""
    from hdrio.grouping import list_images

    if path.is_dir():
        files = list_images(path)
        if not files:
            raise ChainError(f"{path}: folder holds no images")
        chain.brackets.extend(files)
        chain.inputs.extend(files)
        return
    chain.inputs.append(path)
    if path.suffix.lower() in FLOAT_SUFFIXES:
        from hdrio.imageops import read_image

        pixels, header = read_image(path)
        # Carry what describes the pixels (primaries, hdrio's provenance), not the file's
        # layout attributes (data window, screen window...), which the writer sets anew.
        attributes = {name: value for name, value in header.items()
                      if name == "chromaticities" or name.startswith("hdrio:")}
        scale = float(attributes.get("hdrio:exposureScale", 1.0))
        chain.images.append(Image(pixels, attributes, str(path), scale=scale))
    else:
        chain.brackets.append(path)


@operation("--exposures", "LIST", help="exposure times (s) of the pending brackets, in order",
           example="a.jpg b.jpg c.jpg --exposures 1/8,1,8 --merge",
           convert=lambda values: values[0].split(","))
def _exposures(chain: Chain, times: list[str]) -> None:
    chain.settings["exposures"] = times


@operation("--exposures-from", "FILE",
           help="exposures from a sidecar list: CSV (file,exposure_time_s) or OpenCV list.txt",
           example="church_*.png --exposures-from exposures.csv --merge", convert=_one)
def _exposures_from(chain: Chain, path: str) -> None:
    chain.settings["exposures_from"] = path


def _response_name(values: list[str]) -> str:
    from hdrio.response import RESPONSE_METHODS

    return RESPONSE_METHODS.canonical(values[0])


@operation("--response", "METHOD", convert=_response_name,
           help="camera response for the next --merge: Debevec1997 (solved; the default) or "
                "linear (RAW and linear TIFF need no solve; RAW always uses it)",
           example="a.tif b.tif c.tif --response linear --merge")
def _response(chain: Chain, method: str) -> None:
    chain.settings["response"] = method
    chain.settings.pop("response_from", None)


@operation("--response-from", "EXR", convert=_one,
           help="reuse the response stored in an EXR hdrio wrote (no solve)",
           example="d.jpg e.jpg f.jpg --response-from earlier.exr --merge")
def _response_from(chain: Chain, path: str) -> None:
    from hdrio.response.stored import read_response

    chain.settings["response_from"] = read_response(path)


def _multipliers(values: list[str]) -> tuple[float, ...]:
    try:
        numbers = tuple(float(v) for v in values[0].split(","))
    except ValueError:
        raise ValueError("expected R,G,B multipliers, e.g. 2.1,1,1.6") from None
    if len(numbers) != 3 or min(numbers) <= 0:
        raise ValueError("expected three positive multipliers R,G,B")
    return numbers


@operation("--white-balance", "R,G,B", convert=_multipliers,
           help="camera RAW: white-balance multipliers for the set (default: as shot in "
                "its first file)", example="IMG_*.CR3 --white-balance 2.1,1,1.6 --merge")
def _white_balance(chain: Chain, multipliers: tuple[float, ...]) -> None:
    chain.settings["white_balance"] = multipliers


def _mode(choices: tuple[str, ...]) -> Callable[[list[str]], str]:
    def convert(values: list[str]) -> str:
        if values[0] not in choices:
            raise ValueError(f"expected one of {', '.join(choices)}")
        return values[0]
    return convert


@operation("--align", "MODE", convert=_mode(ALIGN_MODES),
           help="registration for the next --merge: auto (the default: warp only if a "
                "bracket moved more than 0.1 px), off, translation, euclidean, homography",
           example="a.jpg b.jpg c.jpg --align euclidean --merge")
def _align(chain: Chain, mode: str) -> None:
    chain.settings["align"] = mode


@operation("--deghost", "MODE", convert=_mode(DEGHOST_MODES),
           help="deghosting for the next --merge: auto (the default) or off",
           example="a.jpg b.jpg c.jpg --deghost off --merge")
def _deghost(chain: Chain, mode: str) -> None:
    chain.settings["deghost"] = mode


# ------------------------------------------------------------------------------ merge


def _merge_domain(token: str) -> bool:
    from hdrio.merge import MERGE_METHODS

    try:
        MERGE_METHODS.canonical(token)
    except KeyError:
        return False
    return True


def _merge_options(values: list[str]) -> str:
    from hdrio.merge import MERGE_METHODS

    return MERGE_METHODS.canonical(values[0]) if values else "log"


@operation("--merge", optional="DOMAIN", accepts_optional=_merge_domain, convert=_merge_options,
           help="merge the pending brackets into scene-linear radiance (domain: log, the "
                "default, or linear)",
           example="a.jpg b.jpg c.jpg --merge linear -o out.exr")
def _merge(chain: Chain, domain: str) -> None:
    from hdrio.io.brackets import read_brackets
    from hdrio.pipeline import MergeOptions, exr_attributes, merge_stack

    if not chain.brackets:
        raise ChainError("no brackets to merge: give the bracket files before --merge")
    settings = chain.settings
    stack = read_brackets(chain.brackets, exposures=settings.pop("exposures", None),
                          exposures_from=settings.pop("exposures_from", None),
                          progress=chain.progress.bar,
                          white_balance=settings.get("white_balance"))
    options = MergeOptions(response=settings.get("response", "Debevec1997"), merge=domain,
                           align=settings.get("align", "auto"),
                           deghost=settings.get("deghost", "auto"))
    result = merge_stack(stack, options, chain.progress.step,
                         response=settings.get("response_from"), owned=True)
    chain.brackets = []
    chain.last_merge = result
    radiance = result.radiance
    if result.colour is not None:  # the input encoding's primaries -> the working space
        from hdrio.cms.stage import output_radiance

        radiance = output_radiance(radiance, result.colour, options.output_space,
                                   options.ocio_config)
    chain.images.append(Image(radiance, exr_attributes(result),
                              f"merge of {stack.count} brackets"))


# ------------------------------------------------------------------------ image steps


@operation("--exposure", "STOPS", convert=_number,
           help="scale the scene-linear image by 2^STOPS", example="--exposure -1.5")
def _exposure(chain: Chain, stops: float) -> None:
    from hdrio.imageops import apply_exposure

    image = chain.top()
    if image.display:
        raise ChainError("the image is display-referred; change exposure before --tonemap")
    image.pixels = apply_exposure(image.pixels, stops)
    image.scale *= 2.0**stops


def _tonemap_arguments(values: list[str]) -> tuple[str, dict[str, float]]:
    from hdrio.tonemap import TONEMAP_METHODS

    name = TONEMAP_METHODS.canonical(values[0])
    parameters: dict[str, float] = {}
    for item in values[1].split(",") if len(values) > 1 else []:
        key, _, text = item.partition("=")
        try:
            parameters[key.strip()] = float(text)
        except ValueError:
            raise ValueError(f"parameter {item!r}: expected NAME=NUMBER") from None
    return name, parameters


@operation("--tonemap", "OPERATOR", optional="NAME=VALUE,...", convert=_tonemap_arguments,
           accepts_optional=lambda token: "=" in token and not token.startswith("-"),
           help="tone-map to a display image (sRGB): reinhard-global, reinhard-local, "
                "their -tutorial variants; optional operator parameters",
           example="--tonemap reinhard-global key=0.18,white=8 -o preview.jpg")
def _tonemap(chain: Chain, value: tuple[str, dict[str, float]]) -> None:
    from hdrio.pipeline import render_preview

    name, parameters = value
    image = chain.top()
    if image.display:
        raise ChainError("the image is already tone-mapped")
    try:
        image.pixels = render_preview(image.pixels, name, **parameters)
    except TypeError:
        raise ChainError(f"{name} takes no parameter {', '.join(parameters)}") from None
    image.display = True


def _size(values: list[str]) -> str:
    if not re.fullmatch(r"\d+(\.\d+)?%|\d+x\d+", values[0]):
        raise ValueError("size must be WIDTHxHEIGHT (0 keeps the aspect) or a percentage")
    return values[0]


@operation("--resize", "SIZE", convert=_size,
           help="resample to WIDTHxHEIGHT (a 0 keeps the aspect ratio) or to N%",
           example="--resize 1024x0")
def _resize(chain: Chain, size: str) -> None:
    from hdrio.imageops import resize

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
    image.pixels = resize(image.pixels, max(1, new_width), max(1, new_height))
