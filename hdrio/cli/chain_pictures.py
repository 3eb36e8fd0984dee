"""Chain operations that draw pictures of the latest merge (PNG, through hdrio.tools.plots)."""

from __future__ import annotations

from hdrio.cli.chain_output import claim_output, output_path
from hdrio.cli.chain_registry import Chain, ChainError, operation
from hdrio.cli.outputs import make_parent


def _check_merge_before(chain: Chain, name: str) -> None:
    if chain.last_merge is None:
        raise ChainError("no merge to draw: put this after --merge")
    _check_name(chain, name)


def _check_name(chain: Chain, name: str) -> None:
    from pathlib import Path

    from hdrio.cli.outputs import check_output

    check_output(Path(name), {".png"}, [str(p) for p in chain.inputs])
    claim_output(chain, name)


def _latest_merge(chain: Chain):
    if chain.last_merge is None:
        raise ChainError("no merge to draw: put this after --merge")
    return chain.last_merge


def _picture_name(values: list[str]) -> str:
    if not values[0].lower().endswith(".png"):
        raise ValueError("pictures are PNG files: name it *.png")
    return values[0]


def _target(chain: Chain, name: str):
    """The picture's path (pattern fields filled in), its folder made."""
    return make_parent(output_path(chain, name))


def _written(chain: Chain, path) -> None:
    chain.progress.step(f"wrote {path}")
    chain.say(f"wrote {path}")


@operation("--plot-response", "PNG", convert=_picture_name,
           check=_check_merge_before,
           help="draw the camera response of the latest --merge per channel, with the "
                "samples of the solve",
           example="a.jpg b.jpg c.jpg --merge --plot-response response.png")
def _plot_response(chain: Chain, name: str) -> None:
    from hdrio.tools.plots import plot_response

    _written(chain, plot_response(_latest_merge(chain), _target(chain, name)))


@operation("--plot-contribution", "PNG", convert=_picture_name, check=_check_merge_before,
           help="map which bracket contributed most to each pixel of the latest --merge",
           example="a.jpg b.jpg c.jpg --merge --plot-contribution brackets.png")
def _plot_contribution(chain: Chain, name: str) -> None:
    from hdrio.tools.plots import plot_contribution

    _written(chain, plot_contribution(_latest_merge(chain), _target(chain, name)))


@operation("--plot-stops", "PNG", convert=_picture_name,
           check=lambda chain, name: (chain.top(), _check_name(chain, name)),
           help="false-colour map of the top image's luminance in stops from its median, "
                "with a legend", example="a.jpg b.jpg c.jpg --merge --plot-stops stops.png")
def _plot_stops(chain: Chain, name: str) -> None:
    from hdrio.tools.plots import plot_stops

    image = chain.top()
    if image.display:
        raise ChainError("the image is tone-mapped; draw stops before --tonemap")
    _written(chain, plot_stops(image.pixels, _target(chain, name)))


@operation("--contact-sheet", "PNG", convert=_picture_name, check=_check_merge_before,
           help="the brackets of the latest --merge side by side, with their exposures",
           example="a.jpg b.jpg c.jpg --merge --contact-sheet brackets_sheet.png")
def _contact_sheet(chain: Chain, name: str) -> None:
    from hdrio.tools.plots import contact_sheet

    _written(chain, contact_sheet(_latest_merge(chain).stack, _target(chain, name)))
