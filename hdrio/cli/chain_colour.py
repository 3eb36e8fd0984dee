"""The chain's colour operations: ``--colorconvert``, ``--colorspace``, ``--ociodisplay``.

OpenColorIO does the work (:mod:`hdrio.cms.spaces`); the config is ``--ocio-config``'s,
else ``$OCIO``, else OCIO's built-in CG config. The image's space is the one its header
records (``hdrio:colorSpace``; linear Rec.709 when it says nothing), and every conversion
rewrites ``chromaticities``, ``colorInteropID``, ``hdrio:colorSpace`` and
``hdrio:ocioConfig`` to match.
"""

from __future__ import annotations

from hdrio.cli.chain import Chain, ChainError, Image, one_argument, operation


def _config(chain: Chain) -> str | None:
    return chain.settings.get("ocio_config")


def _space_of(image: Image) -> str:
    from hdrio.cms.spaces import DEFAULT_WORKING_SPACE

    return str(image.attributes.get("hdrio:colorSpace", DEFAULT_WORKING_SPACE))


def _convert(chain: Chain, image: Image, source: str, target: str) -> None:
    from hdrio.cms import spaces

    if image.display:
        raise ChainError("the image is display-referred (after --tonemap or --ociodisplay); "
                         "convert colour before")
    config = _config(chain)
    image.pixels = spaces.convert(image.pixels, source, target, config)
    image.attributes["hdrio:colorSpace"] = spaces.canonical_space(target, config)
    image.attributes["hdrio:ocioConfig"] = spaces.config_label(config)
    image.attributes["chromaticities"] = spaces.chromaticities(target, config)
    interop = spaces.interop_id(target, config)
    if interop:
        image.attributes["colorInteropID"] = interop
    else:
        image.attributes.pop("colorInteropID", None)


@operation("--ocio-config", "CONFIG", convert=one_argument, per_set=False,
           help="OpenColorIO config (file or ocio:// URI) for the colour operations "
                "(default: $OCIO, else ocio://cg-config-latest)",
           example="--ocio-config ocio://studio-config-latest")
def _ocio_config(chain: Chain, config: str) -> None:
    from hdrio.cms.spaces import load_config

    load_config(config)  # fails here, naming the config, if it cannot be loaded
    chain.settings["ocio_config"] = config


@operation("--colorconvert", "FROM", "TO", convert=lambda values: (values[0], values[1]),
           help="convert the image's pixels from colour space FROM to TO (OpenColorIO names "
                "or aliases) and record TO in the header",
           example="in.exr --colorconvert lin_rec709_scene ACEScg -o acescg.exr")
def _colorconvert(chain: Chain, value: tuple[str, str]) -> None:
    source, target = value
    _convert(chain, chain.top(), source, target)


@operation("--colorspace", "NAME", convert=one_argument,
           help="convert the scene-linear image from the space its header records to NAME "
                "(a scene-linear OpenColorIO space: ACEScg, ACES2065-1, lin_p3d65_scene, ...)",
           example="a.jpg b.jpg c.jpg --merge --colorspace ACEScg -o out.exr")
def _colorspace(chain: Chain, name: str) -> None:
    from hdrio.cms.spaces import require_scene_linear

    image = chain.top()
    require_scene_linear(name, _config(chain))
    _convert(chain, image, _space_of(image), name)


@operation("--ociodisplay", "DISPLAY", "VIEW", convert=lambda values: (values[0], values[1]),
           help="render the scene-linear image through an OpenColorIO display and view "
                "(mid grey at the scene's log-average), giving a display image",
           example="out.exr --ociodisplay 'sRGB - Display' "
                   "'ACES 2.0 - SDR 100 nits (Rec.709)' -o preview.jpg")
def _ociodisplay(chain: Chain, value: tuple[str, str]) -> None:
    from hdrio.cms import spaces
    from hdrio.tonemap.display import preview_OCIO_display

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
    image.display = True
