"""Shared fixtures: the third-party test data folder, and small synthetic bracket sets."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from benchmarks.truth.scenes import data_root  # one place for ../shared/data lookup
from hdrio.io.write import write_image
from hdrio.tools.synthetic import render_brackets

# Four brackets two stops apart; the ramp below is well exposed in at least one of them.
DEFAULT_EXPOSURES = (1 / 16, 1 / 4, 1.0, 4.0)


@pytest.fixture(scope="session")
def shared_data() -> Callable[[str], Path]:
    """``get(name)``: the path of a shared data set, or skip the test when it is absent."""

    def get(name: str) -> Path:
        folder = data_root() / name
        if not folder.is_dir():
            pytest.skip(
                f"../shared/data/{name} not found: third-party test images are read in "
                "place, not shipped; see README"
            )
        return folder

    return get


def tutorial_name(exposure: float, stem: str = "bracket", suffix: str = ".png") -> str:
    """The tutorial's file-name convention: 1/16 s is ``bracket_1_16.png``, 4 s ``bracket_4_1``."""
    ratio = Fraction(exposure).limit_denominator(100_000)
    return f"{stem}_{ratio.numerator}_{ratio.denominator}{suffix}"


def ramp_radiance(height: int, width: int) -> np.ndarray:
    """A smooth, slightly tinted ramp: 0.01 to about 12 (10 stops) left to right."""
    u = np.linspace(0.0, 1.0, width)[np.newaxis, :]
    v = np.linspace(0.0, 1.0, height)[:, np.newaxis]
    luminance = 0.01 * 1000.0**u * (1.0 + 0.2 * v)
    return np.stack([1.05 * luminance, luminance, 0.85 * luminance], axis=-1)


@pytest.fixture
def write_brackets(tmp_path: Path) -> Callable[..., list[Path]]:
    """A helper that writes synthetic RGB brackets of a smooth ramp and returns their paths.

    ``write(exposures=DEFAULT_EXPOSURES, *, names=None, folder=None, size=(48, 64),
    bit_depth=8, suffix=".png", attributes=None)``: file names follow the tutorial's
    convention unless ``names`` are given; ``attributes`` (one mapping per file, or
    ``None``) are stored in the file, e.g. EXIF ``ExposureTime``.
    """

    def write(
        exposures: Sequence[float] = DEFAULT_EXPOSURES,
        *,
        names: Sequence[str] | None = None,
        folder: Path | None = None,
        size: tuple[int, int] = (48, 64),
        bit_depth: int = 8,
        suffix: str = ".png",
        attributes: Sequence[Mapping[str, object] | None] | None = None,
    ) -> list[Path]:
        folder = folder or tmp_path / "brackets"
        folder.mkdir(parents=True, exist_ok=True)
        names = names or [tutorial_name(t, suffix=suffix) for t in exposures]
        attributes = attributes or [None] * len(exposures)
        codes = render_brackets(ramp_radiance(*size), list(exposures), bit_depth=bit_depth)
        pixel_type = "uint8" if bit_depth <= 8 else "uint16"
        return [
            write_image(folder / name, frame, pixel_type, extra)
            for name, frame, extra in zip(names, codes, attributes, strict=True)
        ]

    return write


@pytest.fixture
def brackets(write_brackets) -> list[Path]:
    """Four 48x64 8-bit PNGs of a smooth ramp, 2 stops apart, named by the tutorial's
    convention (``bracket_1_16.png`` .. ``bracket_4_1.png``)."""
    return write_brackets(DEFAULT_EXPOSURES)


@pytest.fixture
def out_dir(tmp_path: Path) -> Path:
    """An empty folder for outputs, so anything left behind is easy to see."""
    folder = tmp_path / "out"
    folder.mkdir()
    return folder


def run_cli(capsys, *argv: object) -> tuple[int, str, str]:
    """``hdrio.cli.main`` on ``argv`` (stringified): exit code, stdout, stderr."""
    from hdrio.cli import main

    code = main([str(arg) for arg in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err
