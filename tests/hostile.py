"""Builders of hostile inputs for the catalogue (tests/test_catalogue.py).

Each builder takes a fresh folder and returns the ``hdrio`` arguments of one case. Bracket
sets are small synthetic ramps (24 x 32, 8-bit, four exposures two stops apart, named by
the tutorial's convention) so the whole catalogue runs in seconds.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from hdrio.io.write import write_exr, write_image
from hdrio.tools.synthetic import render_brackets
from tests.conftest import DEFAULT_EXPOSURES, ramp_radiance, tutorial_name

SIZE = (24, 32)


def ramp_set(folder: Path, channels: int = 3, exposures=DEFAULT_EXPOSURES, size=SIZE,
             bit_depth: int = 8, stem: str = "bracket", suffix: str = ".png") -> list[Path]:
    """Brackets of a smooth ramp (RGB, or its green channel alone when ``channels`` is 1)."""
    folder.mkdir(parents=True, exist_ok=True)
    codes = render_brackets(ramp_radiance(*size), list(exposures), bit_depth=bit_depth)
    if channels == 1:
        codes = codes[..., 1:2]
    pixel_type = "uint8" if bit_depth <= 8 else "uint16"
    return [write_image(folder / tutorial_name(t, stem, suffix), frame, pixel_type)
            for t, frame in zip(exposures, codes)]


def flat_set(folder: Path, value: int, size=SIZE, exposures=DEFAULT_EXPOSURES) -> list[Path]:
    """Brackets whose every code is ``value`` (0: all black, 255: all white)."""
    folder.mkdir(parents=True, exist_ok=True)
    frame = np.full((*size, 3), value, np.uint8)
    return [write_image(folder / tutorial_name(t), frame, "uint8") for t in exposures]


def identical_set(folder: Path) -> list[Path]:
    """Four different exposure times, the same pixels in each file."""
    folder.mkdir(parents=True, exist_ok=True)
    frame = render_brackets(ramp_radiance(*SIZE), [1.0])[0]
    return [write_image(folder / tutorial_name(t), frame, "uint8") for t in DEFAULT_EXPOSURES]


def out(folder: Path, name: str = "out.exr") -> Path:
    """The output folder of a case (made empty, so anything left behind shows)."""
    target = folder / "out"
    target.mkdir(exist_ok=True)
    return target / name


def merge(folder: Path, images, *extra, quiet: bool = True) -> list[object]:
    """``hdrio merge IMAGES -o out/out.exr --preview out/out.jpg -q EXTRA`` (without
    ``-q`` when not ``quiet``: the summary printed)."""
    return ["merge", *images, "-o", out(folder), "--preview", out(folder, "out.jpg"),
            *(["-q"] if quiet else []), *extra]


def saved_response(folder: Path, name: str = "response.exr", channels: int = 3,
                   **changes: object) -> Path:
    """An EXR holding a response as ``hdrio merge`` stores it, with header ``changes``.

    The curve is a plain gamma 2.2 (``g = 2.2 ln(z / codeMax)``) on 256 levels.
    """
    code_max = int(changes.pop("code_max", 255))
    levels = np.arange(256) * (code_max / 255)
    g = 2.2 * np.log(np.maximum(levels, 0.5) / max(code_max, 1))
    names = "RGB" if channels == 3 else "Y"
    attributes: dict[str, object] = {"hdrio:codeMax": code_max,
                                     "hdrio:responseMethod": "Debevec1997",
                                     "hdrio:responseSupport": ", ".join(
                                         f"{n} 1-{code_max - 1}" for n in names)}
    for n in names:
        attributes[f"hdrio:response{n}"] = [float(v) for v in g]
    attributes.update(changes)
    folder.mkdir(parents=True, exist_ok=True)
    return write_exr(folder / name, np.ones((2, 2, 3), np.float32), attributes)


def float_image(folder: Path, name: str = "scene.exr", nan_rows: int = 0,
                inf_pixels: int = 0) -> Path:
    """A scene-linear EXR of the ramp (float), with NaN rows and +Inf pixels when asked."""
    pixels = ramp_radiance(48, 64).astype(np.float32)
    pixels[10:10 + nan_rows] = np.nan
    pixels.reshape(-1, 3)[5:5 + inf_pixels] = np.inf
    folder.mkdir(parents=True, exist_ok=True)
    return write_exr(folder / name, pixels, pixel_type="float")


def unwritable_folder(folder: Path) -> Path:
    """A folder that refuses new files: read-only by its mode, or (for root, whom modes do
    not stop) ``/sys``, which refuses every new file; skip the case when neither works."""
    import pytest

    locked = folder / "locked"
    locked.mkdir(parents=True)
    locked.chmod(0o555)
    try:
        (locked / "probe").touch()
    except OSError:
        return locked
    (locked / "probe").unlink()
    try:
        (Path("/sys") / "hdrio_probe").touch()
    except OSError:
        return Path("/sys")
    pytest.skip("no folder here refuses new files (root, and no /sys)")


def symlink_loop(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    link = folder / "loop_1_1.png"
    os.symlink(link.name, link)
    return link


def text_file(path: Path, data: bytes | str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    path.write_bytes(data)
    return path


def truncated(path: Path) -> Path:
    """``path`` cut to half its length (in place: a fresh copy made for this case)."""
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def grey_exr(folder: Path) -> Path:
    """A one-channel (Y) scene-linear EXR."""
    folder.mkdir(parents=True, exist_ok=True)
    return write_exr(folder / "grey.exr", ramp_radiance(24, 32)[..., 1:2].astype(np.float32))


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (symlinks as their target text) and its content."""
    found: dict[str, bytes] = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            path = Path(root) / name
            key = str(path.relative_to(folder))
            if path.is_symlink():
                found[key] = os.readlink(path).encode()
            elif path.is_file():
                found[key] = path.read_bytes()
            else:
                found[key] = b"<folder>"
    return found
