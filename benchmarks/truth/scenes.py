"""Ground-truth scenes: real scene-linear photographs, read in place and never copied.

The data folder is ``<repo>/../shared/data`` (or ``$HDRIO_TEST_DATA``), the same
convention as ``tests/conftest.py``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPO_ROOT / ".." / "shared" / "data"

#: The six scene-linear photographs of ``openexr_scenes`` (ILM, BSD-3).
SCENES = ("CandleGlass", "Desk", "GoldenGate", "MtTamWest", "StillLife", "Tree")


class DataMissingError(FileNotFoundError):
    """The third-party data folder (or one of its sets) is not where it should be."""


def data_root() -> Path:
    """``../shared/data`` beside the repository, or ``$HDRIO_TEST_DATA`` when set."""
    override = os.environ.get("HDRIO_TEST_DATA")
    return Path(override) if override else DEFAULT_DATA.resolve()


def data_folder(name: str) -> Path:
    """The folder of one shared data set.

    Raises
    ------
    DataMissingError
        With a message saying where the folder was looked for and how to point at it.
    """
    folder = data_root() / name
    if not folder.is_dir():
        raise DataMissingError(
            f"{folder} not found: the truth harness reads third-party images in place from "
            "../shared/data beside the repository (set HDRIO_TEST_DATA to another folder); "
            "they are not shipped with hdrio"
        )
    return folder


@dataclass(frozen=True)
class Scene:
    """A ground-truth radiance image.

    Attributes
    ----------
    name
        Label used in reports (the file stem).
    radiance
        Scene-linear RGB, float32 ``(H, W, 3)``, non-negative.
    source
        The file it was read from.
    """

    name: str
    radiance: np.ndarray
    source: str

    @property
    def log_average(self) -> float:
        """``exp(mean(ln(1e-4 + mean_rgb)))``: the key that the centre exposure maps to 0.18."""
        return float(np.exp(np.mean(np.log(1e-4 + self.radiance.mean(axis=-1)))))


def downsample(image: np.ndarray, width: int | None) -> np.ndarray:
    """Box-filter ``image`` by the integer factor that brings it nearest to ``width`` wide.

    An area average (radiance is additive), so no ringing and no negative values; the
    image is cropped to a multiple of the factor first. ``None`` keeps full resolution.
    """
    if width is None:
        return image
    k = max(1, round(image.shape[1] / width))
    if k == 1:
        return image
    h, w = (image.shape[0] // k) * k, (image.shape[1] // k) * k
    blocks = image[:h, :w].reshape(h // k, k, w // k, k, image.shape[-1])
    return blocks.mean(axis=(1, 3), dtype=np.float64).astype(np.float32)


def read_scene(path: str | Path, width: int | None = None) -> Scene:
    """Read an OpenEXR or Radiance ``.hdr`` file as a ground-truth :class:`Scene`.

    Negative values (Desk and CandleGlass have a few) are clamped to 0, alpha and any
    channel beyond the third are dropped, and a one-channel image is repeated to RGB.
    """
    import OpenImageIO as oiio

    path = Path(path)
    buffer = oiio.ImageBuf(str(path))
    if buffer.has_error or buffer.spec().width == 0:
        raise OSError(f"{path}: cannot read scene ({buffer.geterror() or 'empty image'})")
    pixels = np.asarray(buffer.get_pixels(oiio.FLOAT), dtype=np.float32)
    if pixels.ndim == 2:
        pixels = pixels[..., np.newaxis]
    rgb = pixels[..., :3] if pixels.shape[-1] >= 3 else np.repeat(pixels[..., :1], 3, axis=-1)
    rgb = np.nan_to_num(np.maximum(rgb, 0.0), nan=0.0, posinf=0.0)
    return Scene(path.stem, downsample(np.ascontiguousarray(rgb), width), str(path))


def builtin_scenes(names: tuple[str, ...] = SCENES, width: int | None = None) -> list[Scene]:
    """The ``openexr_scenes`` photographs named ``names``, downsampled to about ``width``."""
    folder = data_folder("openexr_scenes")
    return [read_scene(folder / f"{name}.exr", width) for name in names]
