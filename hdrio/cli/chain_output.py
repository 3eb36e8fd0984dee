"""Chain operations that write, describe and configure: ``-o``, ``-d``, ``--compression``,
``--info``, ``--stats``, and the global settings ``-v``, ``--threads``, ``--dry-run``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hdrio.cli.chain_registry import Chain, ChainError, Image, one_argument, operation
from hdrio.cli.outputs import (
    EXR_SUFFIXES,
    PREVIEW_SUFFIXES,
    check_output,
    lossy_note,
    make_parent,
)
from hdrio.cli.values import positive_whole
from hdrio.io.write import EXR_COMPRESSIONS, exr_compression

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
    return exr_compression(values[0])


@operation("-d", "TYPE", convert=_pixel_type,
           help="pixel type of the following EXR outputs: half or float (default: an "
                "input EXR's own, a float one's float; half for a merge)",
           example="a.jpg b.jpg c.jpg --merge -d float -o float.exr")
def _data_type(chain: Chain, value: str) -> None:
    chain.settings["data_type"] = value


@operation("--compression", "NAME", convert=_compression_name,
           help="compression of the following EXR outputs: "
                f"{', '.join(EXR_COMPRESSIONS)} (default zip; dwaa:45 sets a level)",
           example="a.jpg b.jpg c.jpg --merge --compression piz -o piz.exr")
def _compression(chain: Chain, value: str) -> None:
    chain.settings["compression"] = value


def output_path(chain: Chain, text: str) -> Path:
    """``-o`` argument with the set's pattern fields (``{first_stem}``...) filled in:
    those of ``--group``'s set, else of the chain's inputs so far as one set (stand-ins
    before any: the check of the pattern)."""
    from hdrio.io.paths import fill_pattern, set_fields

    if _pattern_free(Path(text)):
        return Path(text)
    return fill_pattern(text, chain.fields or (set_fields(chain.inputs) if chain.inputs
                                               else PATTERN_FIELDS))


def claim_output(chain: Chain, text: str) -> None:
    """Refuse an output name that an earlier output of the chain (of each set, for a
    pattern) also names: the later write would replace the earlier one. Called by each
    output's check, before any work."""
    from hdrio.io.paths import file_key

    path = output_path(Chain(), text)  # a pattern with stand-in fields: same if same
    claimed = chain.settings.setdefault("_claimed", {})
    key = file_key(path)
    if key in claimed:
        same = "" if claimed[key] == text else f" (as {claimed[key]})"
        raise ChainError(f"{text}: an earlier output of this chain writes this file too"
                         f"{same}; give each output its own name")
    claimed[key] = text


def _check_output(chain: Chain, text: str) -> None:
    image = chain.top()
    claim_output(chain, text)  # (a pattern's syntax and fields checked here, too)
    path = output_path(chain, text)  # a pattern filled in from the inputs so far
    check_output(path, EXR_SUFFIXES | PREVIEW_SUFFIXES,
                 [str(p) for p in chain.inputs] + [str(p) for p in chain.brackets])
    if path.suffix.lower() != ".exr" and not image.display:
        raise ChainError("the image is scene-linear; tone-map it first "
                         "(--tonemap reinhard-global) or write an .exr")
    if _pattern_free(Path(text)):
        chain.settings.setdefault("_written", []).append(str(Path(text)))


@operation("-o", "FILE", convert=_one, check=_check_output,
           help="write the top image (making missing folders): EXR for scene-linear (with "
                "hdrio's header; a tone-mapped image is labelled display-referred), JPEG, "
                "PNG or TIFF for a tone-mapped one; {first_stem}, {last_stem}, {index}, {count} "
                "and {folder} are the brackets' (each set's, with --group)",
           example="a.jpg b.jpg c.jpg --merge -o out.exr --tonemap reinhard-global -o out.jpg")
def _output(chain: Chain, text: str) -> None:
    from hdrio.io.paths import with_relative_sources
    from hdrio.io.write import write_exr, write_preview
    from hdrio.job.output import write_radiance

    image = chain.top()
    path = output_path(chain, text)
    check_output(path, EXR_SUFFIXES | PREVIEW_SUFFIXES, [str(p) for p in chain.inputs])
    if path.suffix.lower() != ".exr" and not image.display:
        raise ChainError("the image is scene-linear; tone-map it first "
                         "(--tonemap reinhard-global) or write an .exr")
    make_parent(path)
    data_type = chain.settings.get("data_type") or image.pixel_type
    compression = chain.settings.get("compression", "zip")
    report = None
    if path.suffix.lower() != ".exr":
        write_preview(path, image.pixels)
    elif image.display:
        pixels = image.pixels if image.alpha is None else np.concatenate(
            [image.pixels, image.alpha], axis=-1)
        write_exr(path, pixels, with_relative_sources(image.attributes, path),
                  pixel_type=data_type, compression=compression, positive=False,
                  channels=image.channels, window=image.window)
    else:
        report = merge_report(image)
        write_radiance(path, image.pixels, image.attributes, pixel_type=data_type,
                       compression=compression, scale=image.scale, alpha=image.alpha,
                       observe=None if report is None else report.add, layers=image.layers,
                       positive=image.statistics is not None,  # a merge's own radiance
                       channels=image.channels, window=image.window)
    chain.progress.step(f"wrote {path}")
    chain.say(f"wrote {path}")
    if report is not None and chain.settings.get("report"):
        from hdrio.cms.checks import format_report

        checked = report.report(str(path))
        lossy = lossy_note(compression, data_type, path)
        if lossy:
            checked.notes.append(lossy)
        chain.say(format_report(checked))


def merge_report(image: Image):
    """A streaming check (:class:`hdrio.cms.checks.StreamingCheck`) of the image's EXR,
    fed band by band as it is written, or ``None`` for an image that is not RGB."""
    from hdrio.cms.checks import StreamingCheck

    if image.pixels.shape[-1] != 3:
        return None
    return StreamingCheck.for_attributes(image.attributes, compiled=True)


# ------------------------------------------------------------------------ information


def _check_info(chain: Chain, _values: list[str]) -> None:
    if not (chain.brackets and not chain.images):
        chain.top()


@operation("--info", help="print what the top image is: size, channels, provenance",
           example="out.exr --info", check=_check_info)
def _info(chain: Chain, _values: list[str]) -> None:
    if not chain.images and chain.brackets:
        count = len(chain.brackets)
        chain.say(f"{count} bracket{'' if count == 1 else 's'} waiting for --merge: "
                  + ", ".join(str(p) for p in chain.brackets))
        return
    image = chain.top()
    height, width, channels = image.pixels.shape
    kind = "display-referred (sRGB)" if image.display else "scene-linear"
    carried = (["alpha"] if image.alpha is not None else []) + list(image.layers) + list(
        image.channels)
    place = "" if image.window is None else f" {image.window}"
    chain.say(f"{image.label}: {width}x{height}{place}, {channels} channels, {kind}"
              + (f"; with {', '.join(carried)}" if carried else ""))
    for name in ("hdrio:responseMethod", "hdrio:exposureSource", "hdrio:mergeDomain"):
        if name in image.attributes:
            chain.say(f"  {name:24s} {image.attribute(name)}")
    sources = image.attribute("hdrio:sourceFiles")
    if sources:
        chain.say(f"  {'hdrio:sourceFiles':24s} {', '.join(map(str, sources))}")


@operation("--stats", help="print per-channel min, max, mean, NaN/Inf/negative counts and "
                           "the dynamic range in stops",
           example="a.jpg b.jpg c.jpg --merge --stats",
           check=lambda chain, _values: chain.top())
def _stats(chain: Chain, _values: list[str]) -> None:
    from hdrio.tools.imageops import image_statistics

    stats = image_statistics(chain.top().pixels)
    for name in ("min", "max", "mean"):
        chain.say(f"  {name:8s} " + " ".join(f"{v:.6g}" for v in stats[name]))
    chain.say(f"  nan {stats['nan']}, inf {stats['inf']}, negative {stats['negative']}")
    if "range_stops" in stats:
        chain.say(f"  range    {stats['range_stops']:.2f} stops (0.1-99.9 percentile: "
                  f"{stats['robust_range_stops']:.2f} stops)")


# ------------------------------------------------------------------- global settings


@operation("-v", help="print each step and its progress on stderr, and a check of each "
                      "merge's EXR as written (as 'hdrio check' prints it)",
           example="-v a.jpg b.jpg c.jpg --merge -o out.exr", per_set=False)
def _verbose(chain: Chain, _values: list[str]) -> None:
    chain.progress.quiet = False
    chain.settings["report"] = True


@operation("--threads", "N", convert=positive_whole, per_set=False,
           help="threads for OpenImageIO, and processes for merging bracket sets (--group)",
           example="--threads 4 a.jpg b.jpg c.jpg --merge -o out.exr")
def _threads(chain: Chain, count: int) -> None:
    import OpenImageIO as oiio

    oiio.attribute("threads", count)
    chain.settings["threads"] = count


@operation("--dry-run", per_set=False,
           help="print the plan (the sets --group finds, what would be written or skipped) "
                "and do nothing", example="shoot/ --group --merge -o {first_stem}.exr --dry-run")
def _dry_run(chain: Chain, _values: list[str]) -> None:
    chain.dry_run = True
