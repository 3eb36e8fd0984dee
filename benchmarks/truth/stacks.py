"""Bracket stacks rendered from a ground-truth scene through a known camera response.

A :class:`StackSpec` names everything that determines a stack (scene, curve, ladder,
bit depth, JPEG); its seed is a hash of that name, so every run renders the same codes.
"""

from __future__ import annotations

import tempfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.truth.curves import Curve
from benchmarks.truth.scenes import Scene
from hdrio.tools.synthetic import DEFAULT_READ_NOISE, DEFAULT_SHOT_NOISE, render_brackets

SHOT_NOISE = DEFAULT_SHOT_NOISE  # variance per unit exposure, relative to full well
READ_NOISE = DEFAULT_READ_NOISE  # standard deviation, relative to full well
JPEG_QUALITY = 90  # libjpeg quality through OpenImageIO, its default 4:2:0 chroma subsampling


@dataclass(frozen=True)
class StackSpec:
    """One bracket stack to render.

    Attributes
    ----------
    scene, curve
        Names of the ground-truth scene and of the camera response.
    frames, ev
        The exposure ladder: ``frames`` brackets ``ev`` stops apart, centred so the
        scene's log-average lands at a sensor exposure of 0.18.
    bits
        Quantisation: 8 or 16.
    jpeg
        8-bit codes round-tripped through JPEG at :data:`JPEG_QUALITY`.
    group
        Which part of the design the stack belongs to (``core``, ``ladder``, ``jpeg``,
        ``16-bit``, ``linear``, ``camera``), for the report.
    camera, noise
        Rendered through that camera's raw clip, white balance and colour matrix
        (:data:`benchmarks.truth.camera.CAMERAS`) at that noise level
        (:data:`benchmarks.truth.camera.NOISE_LEVELS`); ``""``: the plain renderer.
    """

    scene: str
    curve: str
    frames: int = 7
    ev: float = 2.0
    bits: int = 8
    jpeg: bool = False
    group: str = "core"
    camera: str = ""
    noise: str = ""

    @property
    def key(self) -> str:
        encoding = "jpeg" if self.jpeg else f"{self.bits}bit"
        key = f"{self.scene}/{self.curve}/{self.frames}x{self.ev:g}EV/{encoding}"
        return f"{key}/{self.camera}/{self.noise}" if self.camera else key

    @property
    def encoding(self) -> str:
        return "8-bit JPEG" if self.jpeg else f"{self.bits}-bit"

    @property
    def seed(self) -> int:
        return zlib.crc32(self.key.encode()) & 0x7FFFFFFF

    @property
    def code_max(self) -> int:
        return 2**self.bits - 1


@dataclass(frozen=True)
class Stack:
    """A rendered stack: codes ``(P, H, W, 3)`` (RGB, sorted by exposure), times in seconds;
    ``clipped`` ``(P, H, W, 3)``, the observations a camera-like stack clipped in raw."""

    spec: StackSpec
    codes: np.ndarray
    times: np.ndarray
    truth: np.ndarray
    curve: Curve
    clipped: np.ndarray | None = None

    @property
    def code_max(self) -> int:
        return self.spec.code_max


def exposure_ladder(scene: Scene, frames: int, ev: float) -> np.ndarray:
    """``frames`` exposure times ``ev`` stops apart; the middle one maps the key to 0.18."""
    steps = np.arange(frames) - (frames - 1) / 2.0
    return 0.18 / scene.log_average * 2.0 ** (ev * steps)


def jpeg_round_trip(codes: np.ndarray, quality: int = JPEG_QUALITY) -> np.ndarray:
    """Each 8-bit RGB frame written as JPEG (OpenImageIO, libjpeg) and read back."""
    import OpenImageIO as oiio

    out = np.empty_like(codes)
    with tempfile.TemporaryDirectory(prefix="hdrio-truth-") as folder:
        for j, frame in enumerate(codes):
            # One name per frame, read with ImageInput: ImageBuf's cache would hand back
            # the first frame again for a reused name.
            path = str(Path(folder) / f"frame{j}.jpg")
            height, width, channels = frame.shape
            spec = oiio.ImageSpec(width, height, channels, oiio.UINT8)
            spec.attribute("Compression", f"jpeg:{quality}")
            writer = oiio.ImageOutput.create(path)
            if writer is None or not writer.open(path, spec):
                raise OSError(f"cannot write JPEG: {oiio.geterror()}")
            writer.write_image(np.ascontiguousarray(frame))
            writer.close()
            reader = oiio.ImageInput.open(path)
            if reader is None:
                raise OSError(f"cannot read JPEG back: {oiio.geterror()}")
            out[j] = reader.read_image(0, 0, 0, channels, oiio.UINT8).reshape(frame.shape)
            reader.close()
    return out


def render_stack(spec: StackSpec, scene: Scene, curve: Curve) -> Stack:
    """Render ``spec`` with :func:`hdrio.tools.synthetic.render_brackets` (shot and read noise),
    or through its camera (:func:`benchmarks.truth.camera.render_camera_stack`)."""
    if spec.jpeg and spec.bits != 8:
        raise ValueError("JPEG stacks are 8-bit")
    times = exposure_ladder(scene, spec.frames, spec.ev)
    if spec.camera:
        from benchmarks.truth.camera import render_camera_stack

        codes, clipped = render_camera_stack(scene.radiance, times, curve.response,
                                             spec.camera, spec.noise, spec.seed)
        return Stack(spec, codes, times, scene.radiance, curve, clipped)
    codes = render_brackets(scene.radiance, times, curve.response, bit_depth=spec.bits,
                            shot_noise=SHOT_NOISE, read_noise=READ_NOISE, seed=spec.seed)
    if spec.jpeg:
        codes = jpeg_round_trip(codes)
    return Stack(spec, codes, times, scene.radiance, curve)
