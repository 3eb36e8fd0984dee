"""One definition of the options that shape a merge, shared by both front ends.

``hdrio merge BRACKETS... OPTIONS -o out.exr`` and the chain ``hdrio BRACKETS... OPTIONS
--merge -o out.exr`` accept every option of :data:`MERGE_OPTIONS`, with the same name,
arguments and meaning: :func:`add_arguments` puts them on an argparse parser,
:mod:`hdrio.cli.chain_merge` registers each as a chain operation that sets up the next
``--merge``, and both turn the collected values into one
:class:`~hdrio.job.options.MergeOptions` with :func:`merge_options` (which checks names,
colour spaces and combinations before any image is read).

Names follow oiiotool where it has one (``--colorconfig``, ``-d``); older spellings stay
as aliases (``--ocio-config``).

To add an option, append one :class:`Option` to :data:`MERGE_OPTIONS`::

    Option("--lambda", ("N",), "smoothing", positive_number, example=("10",),
           help="smoothness weight lambda of the response solve (default 50)")

``key`` is the :class:`~hdrio.job.options.MergeOptions` field it sets (add the field there
if it is new; a key that is not a field must be handled in :func:`merge_options`);
``convert`` turns the typed arguments (a list of strings) into the value or raises
``ValueError`` with a message; ``example`` is a valid value, which the help shows and
the test that both front ends write the same EXR uses. Nothing else needs changing.
"""

from __future__ import annotations

import argparse
import shlex
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from hdrio.align import ALIGN_MODES, DEGHOST_MODES, REFERENCE_RULE
from hdrio.cli.values import (
    choice,
    encoding_name,
    exposure_list,
    flag,
    integers,
    merge_method,
    nd_filter,
    positive_number,
    positive_whole,
    registry,
    response_methods,
    sampling_methods,
    skip_name,
    text,
    tonemap_arguments,
    weighting_methods,
    white_balance,
    whole,
)
from hdrio.errors import HdrioError
from hdrio.merge.highlights import HIGHLIGHT_HELP, HIGHLIGHT_MODES
from hdrio.merge.saturation import SATURATION_POLICIES

__all__ = ["MERGE_OPTIONS", "OPTIONS_BY_NAME", "Option", "add_arguments", "merge_method",
           "merge_options", "set_value", "settings_from_namespace", "tonemap_arguments"]


@dataclass(frozen=True)
class Option:
    """One merge option: ``name ARG...`` (a flag when ``arguments`` is empty).

    Attributes
    ----------
    name, aliases
        The spelling in help and older spellings that mean the same.
    arguments
        Names of the arguments, as shown in help (``("R,G,B",)``).
    key
        Where the value goes: a :class:`~hdrio.job.options.MergeOptions` field, or one of
        the keys :func:`merge_options` and the readers handle (``exposures``...).
    convert
        ``convert(list_of_argument_strings) -> value``; raises ``ValueError``.
    example
        Valid arguments (also used by the front-end equivalence test).
    repeat
        The option may be given several times; the values collect in a tuple.
    scope
        ``"merge"``: sets up the next merge; ``"global"``: the whole command
        (the chain's colour operations use it too).
    """

    name: str
    arguments: tuple[str, ...]
    key: str
    convert: Callable[[list[str]], Any]
    help: str
    example: tuple[str, ...]
    aliases: tuple[str, ...] = ()
    repeat: bool = False
    scope: str = "merge"
    group: str = "response and merge"
    needs: tuple[str, ...] = ()  # other options it only makes sense with (for examples)

    @property
    def spellings(self) -> tuple[str, ...]:
        return (self.name, *self.aliases)

    def chain_example(self) -> str:
        """A whole chain using the option (what ``hdrio --help`` shows after ``hdrio``)."""
        if self.name == "--merge":
            words = ["a.jpg", "b.jpg", "c.jpg", "--merge", *self.example]
        else:
            words = ["a.jpg", "b.jpg", "c.jpg", *self.needs, self.name, *self.example,
                     "--merge"]
        return shlex.join([*words, "-o", "out.exr"])

    def parse(self, values: list[str]) -> Any:
        """``convert(values)``; a ``ValueError`` or ``KeyError`` becomes one line naming
        the option and its arguments."""
        try:
            return self.convert(values)
        except (ValueError, KeyError) as error:
            message = error.args[0] if error.args else str(error)
            raise HdrioError(f"{' '.join([self.name, *values])}: {message}") from None


# ---------------------------------------------------------------------------- the table

_COLOUR = "colour (see docs/colour.md)"
_EXPOSURE = "exposures"

MERGE_OPTIONS: tuple[Option, ...] = (
    Option("--exposures", ("LIST",), "exposures", exposure_list, example=("1/8,1,8",),
           group=_EXPOSURE, help="exposure times in seconds, in image order, separated by "
                                 "commas (1/8,1,8) or spaces ('1/8 1 8'), or every one as a "
                                 "step in EV (-3EV,0EV,+3EV: relative exposures, 0 EV's 1); "
                                 "wins over every other source"),
    Option("--exposures-from", ("FILE",), "exposures_from", text, group=_EXPOSURE,
           example=("exposures.csv",),
           help="exposures from a sidecar list: CSV (file,exposure_time_s; or filename,"
                "shutter and the like; commas, semicolons or tabs) or OpenCV list.txt"),
    Option("--exposures-from-data", (), "exposures_from_data", flag, example=(),
           group=_EXPOSURE,
           help="merge with each bracket's exposure estimated from the overlap of "
                "well-exposed pixels (anchored to the metadata's; a bracket more than 1/6 "
                "stop from its metadata is named either way); with no metadata at all (3 "
                "brackets or more), infer them: brightness order, the step rounded to 1/3 "
                "stop when the ratios agree on one, relative exposures (the middle bracket "
                "= 1); the sRGB curve (linear for 16-bit) sets the scale, so a camera "
                "whose curve differs can get the step wrong: give the nominal step with "
                "--exposures then (docs/method.md); when only some files have an EXIF "
                "exposure time, those fix the unit (seconds) and, two or more, the step"),
    Option("--nd", ("STOPS[:PATTERN]",), "nd", nd_filter, example=("1:c.jpg",),
           repeat=True, group=_EXPOSURE,
           help="the brackets whose name matches PATTERN (all without one) were shot "
                "through a neutral-density filter of STOPS stops (ND 3.0 = ND1000 = 10); "
                "its true level and colour cast are measured where they overlap the "
                "unfiltered brackets, and corrected (repeatable; PATTERN: a file name or "
                "its stem, shell wildcards, any case, e.g. 'sun_*.jpg' or IMG_0961)"),
    Option("--response", ("METHOD",), "response", registry(response_methods),
           example=("linear",),
           help="camera response: Debevec1997 (solved; the default), Robertson2003 "
                "(Debevec's refined by maximum likelihood with the stack's noise model; "
                "no better on the truth harness, docs/accuracy.md) or linear (RAW and "
                "linear TIFF need no solve; RAW always uses it)"),
    Option("--response-from", ("EXR",), "response_from", text, example=("out.exr",),
           help="reuse the camera response saved in an EXR hdrio wrote (no solve)"),
    Option("--lambda", ("N",), "smoothing", positive_number, example=("10",),
           help="smoothness weight lambda of the response solve (default 50)"),
    Option("--samples", ("N",), "samples", positive_whole, example=("500",),
           help="pixels sampled for the solve (default 1000; 'tutorial' sampling computes "
                "its own)"),
    Option("--sampling", ("METHOD",), "sampling", registry(sampling_methods),
           example=("tutorial",), help="sample selection for the solve (default stratified)"),
    Option("--weighting", ("METHOD",), "weighting", registry(weighting_methods),
           example=("tutorial-hat",), help="weighting function (default Debevec1997)"),
    Option("--merge", ("METHOD",), "merge", merge_method, example=("log",),
           help="merge estimator: inverse-variance (default: weights from the stack's own "
                "noise model), Poisson, log (the tutorial's) or linear; in a chain, "
                "--merge's own optional argument"),
    Option("--align", ("MODE",), "align", choice(*ALIGN_MODES), example=("off",),
           help=f"register the brackets to {REFERENCE_RULE}: auto (measure; warp only if "
                "some bracket moved more than 0.1 px; a bracket too clipped to register "
                "is merged only where no registered one sees the scene, and named), off, "
                "or a model to warp with: translation, euclidean or homography "
                "(default auto)"),
    Option("--deghost", ("MODE",), "deghost", choice(*DEGHOST_MODES), example=("auto",),
           help="drop observations that disagree with the reference bracket (moving "
                "people, leaves): auto or off (default auto)"),
    Option("--motion-layer", (), "motion_layer", flag, example=(),
           help="also write the deghosting mask as the EXR channel motion.Y (1: some "
                "bracket dropped for motion)"),
    Option("--uncertainty", (), "uncertainty", flag, example=(),
           help="also write each pixel's predicted relative standard deviation (from the "
                "noise model) as the EXR layer 'uncertainty', summarised by hdrio check"),
    Option("--saturation", ("POLICY",), "saturation", choice(*SATURATION_POLICIES),
           example=("pixel",),
           help="which observations near clipping are dropped, from their bracket and "
                "every longer one: 'auto' (default: a partly clipped observation whole "
                "where its other channels disagree with the next shorter bracket's, else "
                "its clipped channels alone), 'safe' (the whole observation unless every "
                "channel is below its own white level, found in the data), 'pixel' (the "
                "tutorial's: any channel at the top code) or 'channel' (a channel at the "
                "top code alone; wrong hues where a camera mixes channels); "
                "docs/highlights.md"),
    Option("--clip-mask", (), "clip_mask", flag, example=(),
           help="also write the pixels clipped in every bracket (merged to a neutral "
                "lower bound) as the EXR channel clipped.Y, counted by hdrio check"),
    Option("--highlights", ("MODE",), "highlights", choice(*HIGHLIGHT_MODES),
           example=("reconstruct",),
           help="pixels with channels clipped in every bracket: 'clip' (default: "
                f"{HIGHLIGHT_HELP['clip']}) or 'reconstruct' ({HIGHLIGHT_HELP['reconstruct']}"
                "; a clipped channel never below its clip's lower bound; docs/highlights.md)"),
    Option("--exclude-color", ("R,G,B",), "exclude_colour", integers(3, "R,G,B codes"),
           example=("0,0,255",), aliases=("--exclude-colour",),
           help="keep pixels of this code value out of the solve, registration and "
                "the merge (e.g. "
                "0,0,255 for registration borders): filled from the brackets where they "
                "are not that colour; where every bracket is, alpha 0 (counted apart)"),
    Option("--mask", ("FILE",), "masks", text, example=("mask.png",), repeat=True,
           help="keep a mask's black pixels (below half range) out of the solve, "
                "registration and the merge, as --exclude-color does: one file for every "
                "bracket, the option "
                "repeated once per bracket in their order, or a name with {stem} (each "
                "bracket's file stem: masks/{stem}.png); a bracket's own mask moves with "
                "it when --align warps it, a shared one is on the reference bracket"),
    Option("--seed", ("N",), "seed", whole, example=("7",), help="sampling seed (default 0)"),
    Option("--no-skip", ("NAME",), "no_skip", skip_name, example=("all",), repeat=True,
           help="turn off one of the work skips (repeatable): brackets, covered, response, "
                "channels, early-stop, or all (see docs/speed.md)"),
    Option("--colorspace", ("NAME",), "output_space", text, example=("ACEScg",),
           group=_COLOUR,
           help="OpenColorIO scene-linear space of the EXR, e.g. ACEScg, ACES2065-1 "
                "(default lin_rec709_scene)"),
    Option("--colorconfig", ("CONFIG",), "ocio_config", text, scope="global",
           example=("ocio://cg-config-latest",), aliases=("--ocio-config",), group=_COLOUR,
           help="OpenColorIO config, file or ocio:// URI (default: $OCIO, else "
                "ocio://cg-config-latest)"),
    Option("--input-encoding", ("NAME",), "input_encoding", encoding_name,
           example=("Display P3",), group=_COLOUR,
           help="encoding of the brackets when their ICC profile and EXIF do not say, or "
                "their profile is of one hdrio does not read (ProPhoto RGB): sRGB "
                "(default), 'Adobe RGB (1998)', 'Display P3', Rec.2020"),
    Option("--white-balance", ("X,Y,W,H|R,G,B",), "white_balance", white_balance,
           example=("8,8,16,16",), group=_COLOUR,
           help="X,Y,W,H: make this region neutral grey; R,G,B: camera RAW white-balance "
                "multipliers (default: the camera's as-shot balance)"),
    Option("--absolute", ("SOURCE",), "absolute", choice("exif", "luminance", "illuminance"),
           example=("exif",), group=_COLOUR,
           help="write cd/m^2: from EXIF (t, N, ISO and --meter-k), or a --reference-region "
                "of known --reference-luminance, or a grey card of --reference-reflectance "
                "under --reference-illuminance"),
    Option("--meter-k", ("K",), "meter_k", positive_number, example=("14",), group=_COLOUR,
           needs=("--absolute", "exif"),
           help="reflected-light meter calibration constant (default 12.5)"),
    Option("--reference-region", ("X,Y,W,H",), "reference_region",
           integers(4, "a region X,Y,W,H"), example=("8,8,16,16",), group=_COLOUR,
           needs=("--absolute", "luminance", "--reference-luminance", "100"),
           help="region of known luminance or of a grey card, for --absolute"),
    Option("--reference-luminance", ("CD_M2",), "reference_luminance", positive_number,
           example=("100",), group=_COLOUR,
           needs=("--absolute", "luminance", "--reference-region", "8,8,16,16"),
           help="luminance of --reference-region"),
    Option("--reference-illuminance", ("LUX",), "reference_illuminance", positive_number,
           example=("500",), group=_COLOUR,
           needs=("--absolute", "illuminance", "--reference-region", "8,8,16,16"),
           help="illuminance on the grey card"),
    Option("--reference-reflectance", ("R",), "reference_reflectance", positive_number,
           example=("0.18",), group=_COLOUR,
           needs=("--absolute", "illuminance", "--reference-region", "8,8,16,16",
                  "--reference-illuminance", "500"), help="grey card reflectance (default 0.18)"),
)

OPTIONS_BY_NAME: dict[str, Option] = {
    spelling: option for option in MERGE_OPTIONS for spelling in option.spellings}
_CALIBRATION_KEYS = ("absolute", "meter_k", "reference_region", "reference_luminance",
                     "reference_illuminance", "reference_reflectance")


# --------------------------------------------------------------------------- front ends


def add_arguments(parser: argparse.ArgumentParser, skip: Iterable[str] = (),
                  options: Sequence[Option] = MERGE_OPTIONS) -> None:
    """Put every option of ``options`` (but those named in ``skip``) on ``parser``; read
    them back with :func:`settings_from_namespace`."""
    groups: dict[str, Any] = {}
    for option in options:
        if option.name in skip:
            continue
        group = groups.get(option.group) or parser.add_argument_group(option.group)
        groups[option.group] = group
        if not option.arguments:  # a flag: convert([]) gives its value
            kind: dict[str, Any] = {"action": "append_const" if option.repeat
                                    else "store_const", "const": []}
        else:
            kind = {"action": "append" if option.repeat else "store",
                    "nargs": len(option.arguments) if len(option.arguments) > 1 else None,
                    "metavar": option.arguments[0] if len(option.arguments) == 1
                    else option.arguments}
        group.add_argument(*option.spellings, dest=f"option:{option.key}",
                           default=argparse.SUPPRESS, **kind,
                           help=f"{option.help} (e.g. "
                                f"{shlex.join([option.name, *option.example])})".replace("%", "%%"))


def settings_from_namespace(args: argparse.Namespace,
                            options: Sequence[Option] = MERGE_OPTIONS) -> dict[str, Any]:
    """The values :func:`add_arguments` parsed, converted, by key (only those given)."""
    settings: dict[str, Any] = {}
    for option in options:
        raw = getattr(args, f"option:{option.key}", None)
        if raw is None:
            continue
        items = raw if option.repeat else [raw]
        values = [option.parse(item if isinstance(item, list) else [item]) for item in items]
        settings[option.key] = tuple(values) if option.repeat else values[0]
    return settings


def set_value(settings: dict[str, Any], option: Option, value: Any) -> None:
    """Record ``value`` for ``option`` in ``settings`` (repeatable options accumulate)."""
    if option.repeat:
        settings[option.key] = (*settings.get(option.key, ()), value)
    else:
        settings[option.key] = value


def merge_options(settings: Mapping[str, Any]):
    """The :class:`~hdrio.job.options.MergeOptions` for ``settings`` (keys of the table).

    Checks what single values cannot show: the colour space against the config,
    the ``--absolute`` references, ``--exposures`` with ``--exposures-from``. Raises
    :class:`~hdrio.errors.HdrioError` naming the option; reads no image.
    """
    from hdrio.cms.calibration import Calibration
    from hdrio.cms.spaces import require_scene_linear
    from hdrio.job.options import MergeOptions
    from hdrio.skips import SKIPS

    if settings.get("exposures") is not None and settings.get("exposures_from") is not None:
        raise HdrioError("--exposures and --exposures-from: give one of them")
    known = {f.name for f in fields(MergeOptions)}
    values = {key: value for key, value in settings.items() if key in known}
    if "no_skip" in values:
        values["no_skip"] = tuple(SKIPS) if "all" in values["no_skip"] else values["no_skip"]
    balance = settings.get("white_balance")
    if balance is not None and len(balance) == 3:  # R,G,B: camera RAW multipliers
        values["white_balance"], values["raw_multipliers"] = None, tuple(balance)
    if settings.get("absolute"):
        from hdrio.cms.calibration import DEFAULT_K

        values["calibration"] = Calibration(
            method=settings["absolute"], K=settings.get("meter_k", DEFAULT_K),
            region=settings.get("reference_region"),
            luminance=settings.get("reference_luminance"),
            illuminance=settings.get("reference_illuminance"),
            reflectance=settings.get("reference_reflectance", 0.18))
    elif any(key in settings for key in _CALIBRATION_KEYS):
        given = next(key for key in _CALIBRATION_KEYS if key in settings)
        raise HdrioError(f"--{given.replace('_', '-')} needs --absolute")
    response_from = settings.get("response_from")
    if response_from is not None and Path(response_from).exists():
        from hdrio.radiometry.saved_response import read_response

        try:
            read_response(response_from)  # the header only
        except HdrioError as error:
            raise HdrioError(f"--response-from {response_from}: {error}") from None
    config = settings.get("ocio_config")
    if config is not None:
        from hdrio.cms.spaces import load_config

        load_config(config)  # fails here, naming the config, if it cannot be loaded
    try:
        values["output_space"] = require_scene_linear(
            values.get("output_space", MergeOptions.output_space), config)
    except (HdrioError, KeyError, ValueError) as error:
        message = error.args[0] if error.args else error
        raise HdrioError(f"--colorspace {values.get('output_space')}: {message}") from None
    return MergeOptions(**values)
