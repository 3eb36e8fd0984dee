"""Hard cases for the noise model, alignment and deghosting, with their ground truth.

Captures nobody tuned for (issue 28), rendered from real scene-linear photographs
(``../shared/data/openexr_scenes``) or a procedural night scene through a camera-like
pipeline: photon and read noise in electrons of a full well, the black level clipping
the noise at 0, optional noise reduction (a blur, stronger in chroma, as a phone's),
a tone curve, 8-bit JPEG (quality 90, OpenImageIO's libjpeg), 8-bit PNG or 16-bit codes.

* :func:`night_stack`: a phone's night bracket (9 frames, 1/250 to 1 s, ISO-1000-like
  noise, noise reduction, a strongly toed S-curve), a dark metal grating that the 1 s
  frame shows at codes 5-30 and a lamp;
* :func:`tripod_stack`: a still tripod ladder with real-looking noise, JPEG, PNG or
  16-bit (linear);
* :func:`hand_held`: a hand-held 7-9 x 2 EV ladder with a sun, each bracket moved by up
  to 6 px and rotated by up to 0.3 deg;
* :func:`movers`: a still ladder with a textured object, 4x brighter or 1/4 as bright as
  the background, large (about 5 % of the frame) or small, at a different place in
  each of ``crossing`` brackets.

Truth is measured in the frame of the bracket the others were registered to
(:meth:`HardCase.truth_in`), and a mover against the one bracket's scene it fits best
(:func:`mover_error`); :func:`movers_kept` counts the brackets whose view of a mover the
merge shows, the test that no mover is kept from two brackets reads.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.ndimage

from hdrio.stack import ExposureStack


def srgb(x: np.ndarray) -> np.ndarray:
    """sRGB's encoding curve on [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def phone_curve(x: np.ndarray, contrast: float = 1.5) -> np.ndarray:
    """sRGB then an S-curve, ``y^a / (y^a + (1 - y)^a)``: shadows crushed (1 % of white
    lands at code 9, not 25: a strong toe) and a soft shoulder."""
    y = srgb(x)
    return y**contrast / (y**contrast + (1.0 - y) ** contrast)


@dataclass
class Camera:
    """A sensor and its encoding: ``full_well`` and ``read`` in electrons; ``blur`` the
    noise reduction's Gaussian (pixels, luminance; chroma 2.5x); ``curve`` on [0, 1];
    ``encoding`` ``jpeg``, ``png`` (8-bit) or ``16-bit``."""

    full_well: float = 20_000.0
    read: float = 4.0
    blur: float = 0.0
    curve: object = srgb
    encoding: str = "png"

    @property
    def suffix(self) -> str:
        return {"jpeg": ".jpg", "png": ".png"}.get(self.encoding, ".tif")

    @property
    def code_max(self) -> int:
        return 65535 if self.encoding == "16-bit" else 255

    def capture(self, radiance: np.ndarray, exposure: float, rng) -> np.ndarray:
        """Codes ``(H, W, 3)`` of ``radiance`` (relative to full well per second)."""
        X = np.asarray(radiance, np.float64) * exposure
        sigma = np.sqrt(np.clip(X, 0, 1) / self.full_well + (self.read / self.full_well) ** 2)
        X = np.clip(X + rng.standard_normal(X.shape) * sigma, 0.0, 1.0)  # black, white
        if self.blur:
            luma = X.mean(axis=-1, keepdims=True)
            chroma = X - luma
            luma = scipy.ndimage.gaussian_filter(luma, (self.blur, self.blur, 0))
            chroma = scipy.ndimage.gaussian_filter(chroma, (2.5 * self.blur,) * 2 + (0,))
            X = np.clip(luma + chroma, 0.0, 1.0)
        codes = np.rint(self.curve(X) * self.code_max)
        return np.clip(codes, 0, self.code_max).astype(
            np.uint16 if self.code_max > 255 else np.uint8)


@dataclass
class HardCase:
    """A rendered stack and its truth.

    Attributes
    ----------
    scenes
        ``(P, H, W, 3)`` the radiance each bracket saw, in its own frame (relative).
    warps
        ``(P, 3, 3)`` ``x_bracket = W x_frame`` from a common frame (the identity for
        a tripod).
    objects
        Per bracket, the footprint ``(H, W)`` of the moving object in the common frame
        (``None`` where the bracket does not show it).
    """

    name: str
    codes: np.ndarray
    exposures: np.ndarray
    scenes: np.ndarray
    camera: Camera
    warps: np.ndarray
    objects: list = field(default_factory=list)
    background: np.ndarray | None = None

    def stack(self) -> ExposureStack:
        files = [f"{self.name}_{j}{self.camera.suffix}" for j in range(len(self.exposures))]
        return ExposureStack.from_arrays(self.codes, self.exposures, files=files,
                                         code_max=self.camera.code_max)

    def corner_errors(self, alignment) -> list[float]:
        """Each bracket's measured warp (``alignment``:
        :class:`hdrio.align.registration.Alignment`) against its true one: how far it
        moves a corner of the image (px)."""
        from hdrio.align.lucaskanade import corner_motion

        height, width = self.codes.shape[1:3]
        inverse = np.linalg.inv(self.warps[alignment.reference])
        return [corner_motion(np.linalg.inv(warp @ inverse) @ measured, height, width)
                for warp, measured in zip(self.warps, alignment.transforms)]

    def truth_in(self, reference: int) -> np.ndarray:
        """The still scene in bracket ``reference``'s frame (``(H, W, 3)``)."""
        return self.scenes[reference] if self.background is None else self.background


def _render(name, scenes, exposures, camera, seed, warps=None, objects=(), background=None):
    rng = np.random.default_rng(seed)
    codes = np.stack([camera.capture(s, t, rng) for s, t in zip(scenes, exposures)])
    if camera.encoding == "jpeg":
        from benchmarks.truth.stacks import jpeg_round_trip

        codes = jpeg_round_trip(codes)
    count = len(exposures)
    warps = np.repeat(np.eye(3)[None], count, 0) if warps is None else np.asarray(warps)
    return HardCase(name, codes, np.asarray(exposures, np.float64), np.asarray(scenes),
                    camera, warps, list(objects) or [None] * count, background)


def night_scene(height: int = 240, width: int = 320, seed: int = 0) -> np.ndarray:
    """A dark street at night (relative to full well per second): dim textured walls, a
    metal grating (a fine grid, 0.5-3 % of full well a second), a lit window and a
    lamp."""
    from hdrio.tools.synthetic import demo_scene

    scene = demo_scene(height, width, seed).astype(np.float64) * 0.02
    y, x = np.mgrid[0:height, 0:width]
    grating = (y > 0.55 * height) & (x > 0.55 * width) & (x < 0.95 * width)
    bars = ((x // 3) % 2 == 0) | ((y // 5) % 3 == 0)
    level = np.where(bars, 0.005, 0.03)[..., None] * np.array([0.9, 1.0, 1.1])
    scene[grating] = level[grating]
    return scene


def night_stack(seed: int = 0, encoding: str = "jpeg", height: int = 240,
                width: int = 320) -> HardCase:
    """A phone's manual night bracket on a tripod: 9 frames 1/250 to 1 s, a small
    full well at high gain (800 e-, 2.5 e- read noise: ISO 1000 on a phone sensor),
    noise reduction, :func:`phone_curve`."""
    camera = Camera(full_well=800.0, read=2.5, blur=0.8, curve=phone_curve,
                    encoding=encoding)
    exposures = 250.0 ** (np.linspace(-1.0, 0.0, 9))
    scene = night_scene(height, width, seed)
    return _render(f"night{seed}_{encoding}", [scene] * 9, exposures, camera, seed)


def scene_crop(name: str, height: int, width: int, top: int = 0, left: int = 0
               ) -> np.ndarray:
    """``(height, width, 3)`` of an ``openexr_scenes`` photograph, 2x2 area-averaged."""
    from tests.align_truth import scene_crop as crop

    hi = crop(name, height, width, top, left)
    return hi.reshape(height, 2, width, 2, 3).mean(axis=(1, 3)).astype(np.float64)


def ladder(scene: np.ndarray, frames: int, ev: float = 2.0) -> np.ndarray:
    """``frames`` exposures ``ev`` apart, the middle one putting the log-average at 18 %
    of full well."""
    key = float(np.exp(np.mean(np.log(1e-4 + scene.mean(axis=-1)))))
    return 0.18 / key * 2.0 ** (ev * (np.arange(frames) - (frames - 1) / 2.0))


def _camera(encoding: str) -> Camera:
    """The default sensor with sRGB codes (``jpeg``, ``png``) or linear ones (``16-bit``)."""
    return Camera(encoding=encoding,
                  curve=(lambda x: np.clip(x, 0, 1)) if encoding == "16-bit" else srgb)


def tripod_stack(encoding: str = "jpeg", seed: int = 0, frames: int = 7,
                 scene: str = "Desk", height: int = 200, width: int = 300) -> HardCase:
    """A still ladder, 2 EV apart, of a real scene: a camera's noise (20,000 e- full
    well, 4 e- read noise), sRGB codes (8-bit JPEG or PNG) or linear 16-bit."""
    camera = _camera(encoding)
    radiance = scene_crop(scene, height, width)
    return _render(f"tripod_{scene}_{encoding}", [radiance] * frames,
                   ladder(radiance, frames), camera, seed)


def linear_still_life(top: int, left: int, frames: int = 7, ev: float = 2.0, seed: int = 0
                      ) -> tuple[HardCase, np.ndarray]:
    """A still linear 16-bit ladder (``frames`` x ``ev``, :func:`tripod_stack`'s camera)
    of a full-resolution StillLife crop at ``(top, left)``: ``(case, its scene)``."""
    from tests.align_truth import scene_crop as crop
    from tests.align_truth import view

    scene = view(crop("StillLife", 200, 300, top, left), np.eye(3)).astype(np.float64)
    return _render("linear_still_life", [scene] * frames, ladder(scene, frames, ev),
                   _camera("16-bit"), seed), scene


def add_sun(radiance: np.ndarray, where=(0.2, 0.8), size: float = 3.0,
            level: float = 3000.0) -> np.ndarray:
    """``radiance`` with a small, very bright disc (``level`` times the log-average),
    ``size`` pixels of radius at the fractions ``where`` (row, column)."""
    height, width = radiance.shape[:2]
    key = float(np.exp(np.mean(np.log(1e-4 + radiance.mean(axis=-1)))))
    y, x = np.mgrid[0:height, 0:width]
    disc = np.exp(-((y - where[0] * height) ** 2 + (x - where[1] * width) ** 2)
                  / (2 * size**2))
    return radiance + (level * key * disc)[..., None] * np.array([1.0, 0.95, 0.85])


def hand_held(frames: int = 7, seed: int = 0, height: int = 200, width: int = 300,
              scene: str = "GoldenGate", shift: float = 6.0, degrees: float = 0.3,
              still: bool = False, lens: float = 0.0, encoding: str = "png") -> HardCase:
    """A hand-held ladder, 2 EV apart, with a sun: every bracket moved by up to
    ``shift`` px and ``degrees`` (``still``: the same stack on a tripod).

    ``lens``: the standard deviation (pixels) of a Gaussian point spread function each
    bracket's view is blurred by before it is captured, as a lens and an anti-aliasing
    filter blur what reaches the sensor (the truth is the blurred view). 0, the default,
    keeps edges as sharp as the 2x2 area average of the supersampled scene: sharper than
    any lens gives, the hardest case for resampling. ``encoding``: ``png`` (sRGB codes)
    or ``16-bit`` (linear codes, as a raw converter writes them)."""
    from tests.align_truth import SUPER, euclidean, view
    from tests.align_truth import scene_crop as crop

    rng = np.random.default_rng(seed)
    hi = crop(scene, height, width, 100, 30)
    hi = add_sun(hi, size=3.0 * SUPER)
    warps = [np.eye(3) if still else euclidean(*rng.uniform(-shift, shift, 2),
                                              rng.uniform(-degrees, degrees), height, width)
             for _ in range(frames)]
    scenes = [view(hi, w).astype(np.float64) for w in warps]
    if lens > 0:
        scenes = [scipy.ndimage.gaussian_filter(s, (lens, lens, 0)) for s in scenes]
    camera = _camera(encoding)
    exposures = ladder(view(hi, np.eye(3)), frames)
    return _render(f"handheld{frames}_{seed}{'_still' if still else ''}"
                   f"{'_linear' if encoding == '16-bit' else ''}"
                   f"{f'_lens{lens:g}' if lens else ''}", scenes, exposures, camera, seed, warps)


def movers(crossing: int = 2, bright: bool = True, large: bool = True, frames: int = 5,
           seed: int = 0, height: int = 200, width: int = 300, scene: str = "Desk"
           ) -> HardCase:
    """A still ladder (2 EV apart) and a textured object, 4x the background's median
    (``bright``) or 1/4 of it, about 5 % of the frame (``large``) or 0.6 %, at a
    different place in each of ``crossing`` brackets (the shortest ones but the
    middle, then the middle); ``background`` is the scene without it."""
    rng = np.random.default_rng(seed)
    background = scene_crop(scene, height, width)
    side = int(np.sqrt((0.05 if large else 0.006) * height * width))
    noise = scipy.ndimage.gaussian_filter(rng.standard_normal((side, side)), 1.5)
    texture = np.exp(0.35 * noise / noise.std())  # a stop or so of texture
    texture = texture / np.median(texture)
    level = (4.0 if bright else 0.25) * float(np.median(background.mean(axis=-1)))
    middle = frames // 2
    order = [j for j in range(frames) if j != middle] + [middle]
    chosen = order[:crossing]
    scenes, objects = [], []
    # Places along a diagonal band, far enough apart that no two footprints overlap.
    slots = [(int(r), int(c)) for r, c in zip(
        np.linspace(0.08 * height, height - side - 0.08 * height, frames),
        np.linspace(0.08 * width, width - side - 0.08 * width, frames)[::-1])]
    slots = [slots[k] for k in rng.permutation(frames)]
    for j in range(frames):
        radiance = background.copy()
        footprint = None
        if j in chosen:
            top, left = slots[j]
            radiance[top:top + side, left:left + side] = \
                (level * texture)[..., None] * np.array([1.0, 0.9, 0.8])
            footprint = np.zeros((height, width), bool)
            footprint[top:top + side, left:left + side] = True
        scenes.append(radiance)
        objects.append(footprint)
    name = (f"mover_{'bright' if bright else 'dark'}_{'large' if large else 'small'}"
            f"_x{crossing}_{seed}")
    return _render(name, scenes, ladder(background, frames), Camera(encoding="png"), seed,
                   objects=objects, background=background)


def walkers(ev: float = 1.0, seed: int = 0, moving: bool = True, frames: int = 3,
            step: float = 0.35, height: int = 200, width: int = 300, scene: str = "Desk"
            ) -> HardCase:
    """A JPEG ladder ``ev`` apart and a dark figure (a tenth of the background's median,
    textured, 45 % of the frame high and 12 % wide) in every bracket, each place
    ``step`` of its width on from the last, so that the places overlap and no bracket shows the
    background behind all of them (people walking through a hall; ``moving`` false: the
    figure stands still). ``background`` is the scene without it."""
    rng = np.random.default_rng(seed)
    background = scene_crop(scene, height, width)
    tall, wide = int(0.45 * height), int(0.12 * width)
    noise = scipy.ndimage.gaussian_filter(rng.standard_normal((tall, wide)), 1.5)
    texture = np.exp(0.35 * noise / noise.std())
    figure = (0.1 * float(np.median(background.mean(axis=-1))) * texture
              / np.median(texture))[..., None] * np.array([0.8, 0.9, 1.0])
    top, left = int(0.3 * height), int(0.4 * width)
    scenes, objects = [], []
    for j in range(frames):
        radiance = background.copy()
        at = left + (round(j * step * wide) if moving else 0)
        radiance[top:top + tall, at:at + wide] = figure
        footprint = np.zeros((height, width), bool)
        footprint[top:top + tall, at:at + wide] = True
        scenes.append(radiance)
        objects.append(footprint)
    return _render(f"walkers_{ev:g}_{seed}{'' if moving else '_still'}", scenes,
                   ladder(background, frames, ev), Camera(encoding="jpeg"), seed,
                   objects=objects, background=background)


def hand_held_walkers(scene: str = "Desk", frames: int = 5, ev: float = 2.0, seed: int = 0,
                      figure: bool = True, shift: float = 4.0, degrees: float = 0.2,
                      height: int = 200, width: int = 300) -> HardCase:
    """:func:`walkers`' figure (a tenth of the crop's median, textured) walking through a
    hand-held JPEG ladder ``ev`` apart, every bracket moved by up to ``shift`` px and
    ``degrees`` (``figure`` false: the same stack without it)."""
    from tests.align_truth import SUPER, euclidean, view
    from tests.align_truth import scene_crop as crop

    rng = np.random.default_rng(seed)
    hi = crop(scene, height, width, 40, 30)
    tall, wide = int(0.45 * height), int(0.12 * width)
    noise = scipy.ndimage.gaussian_filter(rng.standard_normal((tall * SUPER, wide * SUPER)), 3)
    texture = np.exp(0.35 * noise / noise.std())
    person = (0.1 * float(np.median(hi.mean(axis=-1))) * texture
              / np.median(texture))[..., None] * np.array([0.8, 0.9, 1.0])
    top, left = int(0.3 * height), int(0.35 * width)
    warps = [euclidean(*rng.uniform(-shift, shift, 2), rng.uniform(-degrees, degrees),
                       height, width) for _ in range(frames)]
    scenes = []
    for j in range(frames):
        radiance = hi.copy()
        if figure:
            at = left + round(j * 0.35 * wide)
            radiance[top * SUPER:(top + tall) * SUPER, at * SUPER:(at + wide) * SUPER] = person
        scenes.append(view(radiance, warps[j]).astype(np.float64))
    return _render(f"handheld_walkers_{scene}_{frames}_{seed}{'' if figure else '_empty'}",
                   scenes, ladder(view(hi, np.eye(3)), frames, ev), Camera(encoding="jpeg"),
                   seed, warps)


def movers_kept(case: HardCase, radiance: np.ndarray, scale: float = 1.0) -> list[str]:
    """What the merge shows at each bracket's footprint of the object (the footprint's
    inner part, clear of the other footprints), by the median ``ln`` ratio of ``scale *
    radiance`` to the object's and the background's radiance there: ``object`` (that
    bracket's view kept), ``background``, ``bound`` (neither, where the other brackets
    clip at most of it: only their bound on the background is left) or ``blend`` (two
    views mixed)."""
    shown = []
    for j, footprint in enumerate(case.objects):
        if footprint is None:
            continue
        others = np.zeros_like(footprint)
        for k, other in enumerate(case.objects):
            if k != j and other is not None:
                others |= other
        inner = scipy.ndimage.binary_erosion(footprint, iterations=3) & ~others
        if not inner.any():
            continue
        merged = scale * radiance[inner].mean(axis=-1)
        to_object = np.median(np.abs(np.log(merged / case.scenes[j][inner].mean(axis=-1))))
        to_background = np.median(np.abs(np.log(merged / case.background[inner].mean(axis=-1))))
        gap = abs(np.log(np.median(case.scenes[j][inner].mean(axis=-1)
                                   / case.background[inner].mean(axis=-1))))
        clipped = np.mean([np.mean(np.any(case.codes[k][inner] >= case.camera.code_max,
                                          axis=-1)) for k in range(len(case.objects))
                           if k != j])
        if min(to_object, to_background) <= 0.25 * gap:
            shown.append("object" if to_object < to_background else "background")
        else:
            shown.append("bound" if clipped > 0.5 else "blend")
    return shown


def mover_error(case: HardCase, radiance: np.ndarray, scale: float, mask: np.ndarray
                ) -> float:
    """The median relative error of ``scale * radiance`` over the movers' footprints
    (within ``mask``), against the one bracket's scene that fits them best."""
    region = np.zeros(radiance.shape[:2], bool)
    for footprint in case.objects:
        if footprint is not None:
            region |= footprint
    region &= mask
    candidates = [case.background] + [s for s, f in zip(case.scenes, case.objects)
                                       if f is not None]
    return min(float(np.median(np.abs(scale * radiance[region] / scene[region] - 1)))
               for scene in candidates)
