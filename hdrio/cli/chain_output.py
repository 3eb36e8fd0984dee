"""Chain operations that write, describe and configure: ``-o``, ``-d``, ``--compression``,
``--info``, ``--stats``, and the global settings ``-v``, ``--threads``, ``--dry-run``,
``--group``.
"""

from __future__ import annotations

from pathlib import Path

from hdrio.cli.chain import (
    IMAGE_SUFFIXES,
    Chain,
    ChainError,
    Step,
    one_argument,
    operation,
    step_message,
)
from hdrio.cli.commands import _check_outputs
from hdrio.errors import HdrioError

_COMPRESSIONS = ("none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab")
_one = one_argument
# The fields a set's output name may use (hdrio.grouping.BracketSet.fields), with
# stand-in values for checking a pattern before any set is known.
PATTERN_FIELDS = {"first_stem": "first", "last_stem": "last", "index": "1", "count": "2",
                  "folder": "."}


def _pattern_free(path: Path) -> bool:
    from hdrio.io.paths import is_pattern

    return not is_pattern(path)


# ----------------------------------------------------------------------------- output


def _pixel_type(values: list[str]) -> str:
    if values[0] not in ("half", "float"):
        raise ValueError(f"{values[0]!r}: choose half or float")
    return values[0]


def _compression_name(values: list[str]) -> str:
    name, _, level = values[0].lower().partition(":")
    if name not in _COMPRESSIONS or (level and not level.isdigit()):
        raise ValueError(f"{values[0]!r}: choose from {', '.join(_COMPRESSIONS)}")
    return values[0].lower()


@operation("-d", "TYPE", convert=_pixel_type,
           help="pixel type of the following EXR outputs: half (default) or float",
           example="-d float -o out.exr")
def _data_type(chain: Chain, value: str) -> None:
    chain.settings["data_type"] = value


@operation("--compression", "NAME", convert=_compression_name,
           help=f"compression of the following EXR outputs: {', '.join(_COMPRESSIONS)} "
                "(default zip; dwaa:45 sets a level)",
           example="--compression piz -o out.exr")
def _compression(chain: Chain, value: str) -> None:
    chain.settings["compression"] = value


def output_path(chain: Chain, text: str) -> Path:
    """``-o`` argument with the set's pattern fields (``{first_stem}``...) filled in."""
    from hdrio.io.paths import fill_pattern

    if _pattern_free(Path(text)):
        return Path(text)
    return fill_pattern(text, chain.fields or PATTERN_FIELDS)


@operation("-o", "FILE", convert=_one,
           help="write the top image: EXR for scene-linear (with hdrio's header), JPEG, PNG "
                "or TIFF for a tone-mapped one; {first_stem} etc. name each set's output",
           example="-o {first_stem}_hdr.exr")
def _output(chain: Chain, text: str) -> None:
    from hdrio.io.write import write_exr, write_preview
    from hdrio.pipeline import half_safe_scale

    image = chain.top()
    path = output_path(chain, text)
    _check_outputs(path if path.suffix.lower() == ".exr" else None,
                   None if path.suffix.lower() == ".exr" else path,
                   [str(p) for p in chain.inputs])
    if path.suffix.lower() != ".exr":
        if not image.display:
            raise ChainError("the image is scene-linear; tone-map it first "
                             "(--tonemap reinhard-global) or write an .exr")
        write_preview(path, image.pixels)
    else:
        data_type = chain.settings.get("data_type", "half")
        scale = half_safe_scale(image.pixels) if data_type == "half" else 1.0
        attributes = dict(image.attributes)
        if not image.display:
            attributes["hdrio:exposureScale"] = float(image.scale * scale)
        pixels = image.pixels * scale if scale != 1.0 else image.pixels
        write_exr(path, pixels, attributes, pixel_type=data_type,
                  compression=chain.settings.get("compression", "zip"))
    chain.progress.step(f"wrote {path}")
    chain.say(f"wrote {path}")


def check_outputs(steps: list[Step]) -> None:
    """Refuse bad ``-o`` names before any work (type, folder, overwriting an input)."""
    inputs = [str(step.value) for step in steps if step.name == "read"]
    for step in steps:
        if step.name != "-o":
            continue
        path = Path(step.value)
        suffix = path.suffix.lower()
        if suffix not in IMAGE_SUFFIXES | {".exr"}:
            raise ChainError(f"{step.text}: unsupported output type; use .exr, "
                             f"{', '.join(sorted(IMAGE_SUFFIXES))}")
        if not _pattern_free(path):
            try:
                output_path(Chain(), step.value)  # the pattern's syntax, now
            except HdrioError as error:
                raise ChainError(step_message(step, error)) from None
        else:
            try:
                _check_outputs(path if suffix == ".exr" else None,
                               None if suffix == ".exr" else path, inputs)
            except HdrioError as error:
                raise ChainError(step_message(step, error)) from None


# ------------------------------------------------------------------------ information


@operation("--info", help="print what the top image is: size, channels, provenance",
           example="in.exr --info")
def _info(chain: Chain, _values: list[str]) -> None:
    if not chain.images and chain.brackets:
        chain.say(f"{len(chain.brackets)} brackets waiting for --merge: "
                  + ", ".join(str(p) for p in chain.brackets))
        return
    image = chain.top()
    height, width, channels = image.pixels.shape
    kind = "display-referred (sRGB)" if image.display else "scene-linear"
    chain.say(f"{image.label}: {width}x{height}, {channels} channels, {kind}")
    for name in ("hdrio:responseMethod", "hdrio:exposureSource", "hdrio:mergeDomain"):
        if name in image.attributes:
            chain.say(f"  {name:24s} {image.attributes[name]}")
    sources = image.attributes.get("hdrio:sourceFiles")
    if sources:
        chain.say(f"  {'hdrio:sourceFiles':24s} {', '.join(map(str, sources))}")


@operation("--stats", help="print per-channel min, max, mean, NaN/Inf/negative counts and "
                           "the dynamic range in stops", example="--merge --stats")
def _stats(chain: Chain, _values: list[str]) -> None:
    from hdrio.imageops import image_statistics

    stats = image_statistics(chain.top().pixels)
    for name in ("min", "max", "mean"):
        chain.say(f"  {name:8s} " + " ".join(f"{v:.6g}" for v in stats[name]))
    chain.say(f"  nan {stats['nan']}, inf {stats['inf']}, negative {stats['negative']}")
    if "range_stops" in stats:
        chain.say(f"  range    {stats['range_stops']:.2f} stops (0.1-99.9 percentile: "
                  f"{stats['robust_range_stops']:.2f} stops)")


# ------------------------------------------------------------------- global settings


@operation("-v", help="print each step and its progress on stderr", example="-v a.jpg ...",
           per_set=False)
def _verbose(chain: Chain, _values: list[str]) -> None:
    chain.progress.quiet = False


def _count(values: list[str]) -> int:
    if not values[0].isdigit() or int(values[0]) < 1:
        raise ValueError(f"expected a positive whole number, got {values[0]!r}")
    return int(values[0])


@operation("--threads", "N", convert=_count, per_set=False,
           help="threads for OpenImageIO, and processes for merging bracket sets (--group)",
           example="--threads 4")
def _threads(chain: Chain, count: int) -> None:
    import OpenImageIO as oiio

    oiio.attribute("threads", count)
    chain.settings["threads"] = count


@operation("--dry-run", per_set=False,
           help="print the plan (the sets --group finds, what would be written or skipped) "
                "and do nothing", example="shoot/ --group --merge -o {first_stem}.exr --dry-run")
def _dry_run(chain: Chain, _values: list[str]) -> None:
    chain.dry_run = True


@operation("--group", help="split the pending brackets into bracket sets (capture time, "
                           "exposure pattern, sequence) and run the rest of the chain on "
                           "each set, in parallel; sets already done from the same "
                           "inputs and settings are skipped (--force redoes them)",
           example="shoot/ --group --merge -o {first_stem}_hdr.exr")
def _group(chain: Chain, _values: list[str]) -> None:  # run by chain.run_steps
    raise AssertionError("--group is run by run_steps")

