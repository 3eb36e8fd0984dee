"""Pictures of a merge: produced through the chain, and what they show is right."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

pytest.importorskip("matplotlib", reason="pictures need matplotlib (the 'plot' extra)")

import hdrio  # noqa: E402
from hdrio.cli import main  # noqa: E402
from hdrio.response import response_linear  # noqa: E402
from hdrio.stack import ExposureStack  # noqa: E402
from hdrio.tools.plots import dominant_bracket  # noqa: E402
from tests.conftest import DEFAULT_EXPOSURES  # noqa: E402

PICTURES = ("--plot-response", "--plot-contribution", "--plot-stops", "--contact-sheet")


def read_png(path: Path) -> np.ndarray:
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    pixels = image.read_image(0, 0, 0, 3, "uint8")
    image.close()
    return np.asarray(pixels)


@pytest.mark.slow
def test_every_picture_is_written_through_the_chain(write_brackets, tmp_path, capsys):
    brackets = write_brackets(DEFAULT_EXPOSURES)
    argv = [*map(str, brackets), "--merge"]
    for flag in PICTURES:
        argv += [flag, str(tmp_path / f"{flag.strip('-')}.png")]
    assert main(argv) == 0, capsys.readouterr().err
    for flag in PICTURES:
        pixels = read_png(tmp_path / f"{flag.strip('-')}.png")
        height, width, _ = pixels.shape
        assert height > 200 and width > 300  # a figure, not an empty canvas
        # A drawn figure has many colours; a blank or failed one has one or two.
        assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 50, flag


def test_pictures_need_a_merge_and_a_png_name(write_brackets, tmp_path, capsys):
    brackets = write_brackets(DEFAULT_EXPOSURES)
    assert main([str(tmp_path / "nothing.exr"), "--plot-response", "r.png"]) == 2
    assert main([*map(str, brackets), "--merge", "--plot-stops", "s.jpg"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert "--plot-stops s.jpg: pictures are PNG files" in err[-1]


def test_dominant_bracket_follows_brightness_and_saturation():
    # One row of five pixels, three brackets 2 stops apart, 8-bit codes: a dark pixel is
    # best seen in the longest exposure, a bright one in the shortest, a pixel clipped in
    # every bracket in none.
    codes = np.array([
        [[20, 20, 20], [60, 60, 60], [128, 128, 128], [200, 200, 200], [255, 255, 255]],
        [[40, 40, 40], [128, 128, 128], [240, 240, 240], [255, 255, 255], [255, 255, 255]],
        [[80, 80, 80], [220, 220, 220], [255, 255, 255], [255, 255, 255], [255, 255, 255]],
    ], dtype=np.uint8)[:, np.newaxis]
    stack = ExposureStack.from_arrays(codes, [1.0, 4.0, 16.0])
    response = response_linear(stack)
    options = hdrio.MergeOptions()
    result = hdrio.MergeResult(stack, response, np.ones((1, 5, 3), np.float32), None,
                               options, hdrio.plan_merge(options))
    assert dominant_bracket(result).tolist() == [[2, 1, 0, 0, -1]]
