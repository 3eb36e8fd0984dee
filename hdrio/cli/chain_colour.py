"""The chain's colour operations: ``--colorconvert``, ``--colorspace``, ``--ociodisplay``.

OpenColorIO does the work (:mod:`hdrio.cms.spaces`); the config is ``--colorconfig``'s
(a merge option: :mod:`hdrio.cli.merge_arguments`), else ``$OCIO``, else OCIO's built-in CG
config. The image's space is the one its header records (``hdrio:colorSpace``; linear
Rec.709 when it says nothing), and every conversion rewrites the attributes that say
what the pixels are (:func:`hdrio.cms.colour_stage.space_attributes`) to match.
"""

from __future__ import annotations

from hdrio.cli.chain_merge import note_pending
from hdrio.cli.chain_ops import needs_scene_linear
from hdrio.cli.chain_registry import Chain, ChainError, Image, operation
from hdrio.cli.merge_arguments import OPTIONS_BY_NAME, set_value


def _config(chain: Chain) -> str | None:
    return chain.settings.get("ocio_config")


def _space_of(image: Image) -> str:
    from hdrio.cms.spaces import DEFAULT_WORKING_SPACE

    return str(image.attribute("hdrio:colorSpace", DEFAULT_WORKING_SPACE))


def _convert(chain: Chain, image: Image, source: str, target: str) -> None:
    from hdrio.cms import spaces
    from hdrio.cms.colour_stage import space_attributes

    if image.display:
        raise ChainError("the image is display-referred (after --tonemap or --ociodisplay); "
                         "convert colour before")
    config = _config(chain)
    image.pixels = spaces.convert(image.pixels, source, target, config)
    image.statistics = None
    image.attributes.pop("colorInteropID", None)
    image.attributes.update(space_attributes(target, config))


def _check_colorconvert(chain: Chain, value: tuple[str, str]) -> None:
    from hdrio.cms.spaces import canonical_space

    image = needs_scene_linear(chain)
    source, target = (canonical_space(name, _config(chain)) for name in value)
    labelled = image.attribute("hdrio:colorSpace")
    said = None if labelled is None else _canonical_or_none(str(labelled), chain)
    if said is not None and said != source:
        chain.note(f"{image.label} is labelled {labelled}; converted from {value[0]} as "
                   "told")
    image.attributes["hdrio:colorSpace"] = value[1]


def _canonical_or_none(name: str, chain: Chain) -> str | None:
    from hdrio.cms.spaces import canonical_space
    from hdrio.errors import HdrioError

    try:
        return canonical_space(name, _config(chain))
    except HdrioError:  # a space this config does not know: nothing to compare
        return None


@operation("--colorconvert", "FROM", "TO", convert=lambda values: (values[0], values[1]),
           check=_check_colorconvert,
           help="convert the image's pixels from colour space FROM to TO (OpenColorIO names "
                "or aliases) and record TO in the header",
           example="out.exr --colorconvert lin_rec709_scene ACEScg -o acescg.exr")
def _colorconvert(chain: Chain, value: tuple[str, str]) -> None:
    source, target = value
    _convert(chain, chain.top(), source, target)


_COLORSPACE = OPTIONS_BY_NAME["--colorspace"]


def _check_colorspace(chain: Chain, name: str) -> None:
    from hdrio.cms.spaces import require_scene_linear

    canonical = require_scene_linear(name, _config(chain))
    if chain.brackets:
        set_value(chain.settings, _COLORSPACE, name)
        note_pending(chain, "--colorspace")
    else:
        needs_scene_linear(chain).attributes["hdrio:colorSpace"] = canonical


@operation("--colorspace", "NAME", convert=_COLORSPACE.parse, check=_check_colorspace,
           help="the scene-linear OpenColorIO space (ACEScg, ACES2065-1, lin_p3d65_scene, "
                "...): before --merge, the merge's working space (as 'hdrio merge "
                "--colorspace'); after, converts the image from the space its header records",
           example="a.jpg b.jpg c.jpg --colorspace ACEScg --merge -o out.exr")
def _colorspace(chain: Chain, name: str) -> None:
    from hdrio.cms.spaces import require_scene_linear

    require_scene_linear(name, _config(chain))
    if chain.brackets:  # waiting for --merge: its working space
        set_value(chain.settings, _COLORSPACE, name)
        return
    image = chain.top()
    _convert(chain, image, _space_of(image), name)


def _check_ociodisplay(chain: Chain, value: tuple[str, str]) -> None:
    from hdrio.cms.spaces import display_view_names

    display_view_names(*value, _config(chain))
    needs_scene_linear(chain).display = True


@operation("--ociodisplay", "DISPLAY", "VIEW", convert=lambda values: (values[0], values[1]),
           check=_check_ociodisplay,
           help="render the scene-linear image through an OpenColorIO display and view "
                "(mid grey at the scene's log-average), giving a display image",
           example="out.exr --ociodisplay 'sRGB - Display' "
                   "'ACES 2.0 - SDR 100 nits (Rec.709)' -o preview.jpg")
def _ociodisplay(chain: Chain, value: tuple[str, str]) -> None:
    from hdrio.cms import spaces
    from hdrio.cms.colour_stage import display_attributes
    from hdrio.cms.display import preview_OCIO_display

    display, view = value
    image = chain.top()
    if image.display:
        raise ChainError("the image is already display-referred")
    config = _config(chain)
    space = _space_of(image)
    colourspace = spaces.colour_science_name(space, config)
    if colourspace is None:
        raise ChainError(f"{space}: no colour-science primaries known for its luminance")
    image.pixels = preview_OCIO_display(image.pixels, space, display, view,
                                        colourspace=colourspace, config=config)
    image.attributes = display_attributes(image.attributes, f"{display} / {view}",
                                          display, config)
    image.display, image.statistics = True, None
