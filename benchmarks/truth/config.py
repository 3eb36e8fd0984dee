"""The fixed designs: which stacks a run renders (``quick``, ``full``) and how often it times.

The full design crosses every scene with every curve at the reference ladder (7 frames,
2 EV, 8-bit) and varies one factor at a time around it on subsets: the ladder, JPEG, 16
bits. Each stack is named by its :class:`~benchmarks.truth.stacks.StackSpec` and seeded
from that name, so runs repeat exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from benchmarks.truth.curves import CURVES
from benchmarks.truth.scenes import SCENES
from benchmarks.truth.stacks import StackSpec

LADDERS = tuple((frames, ev) for frames in (3, 5, 7, 9) for ev in (1.0, 2.0, 3.0))
REFERENCE_LADDER = (7, 2.0)


@dataclass(frozen=True)
class Config:
    """A run: the stacks, the scene width, and how often each method is timed.

    Attributes
    ----------
    name
        ``quick``, ``full`` or ``custom``.
    stacks
        What to render, in order.
    width
        Scenes are box-downsampled by an integer factor to at least this width
        (``None`` = full resolution).
    repeats
        Timed calls per (stack, method) on the ``timed_groups`` stacks (one call on the
        others); the time is their median, after one untimed warm-up call per method on
        its first stack.
    scene_paths
        User scenes (``--scene``) by name; built-in ``openexr_scenes`` otherwise.
    methods
        Method names to run (``None`` = all).
    """

    name: str
    stacks: tuple[StackSpec, ...]
    width: int | None
    repeats: int
    scene_paths: dict[str, str] = field(default_factory=dict)
    methods: tuple[str, ...] | None = None
    timed_groups: tuple[str, ...] = ("core",)

    def repeats_for(self, spec: StackSpec) -> int:
        return self.repeats if spec.group in self.timed_groups else 1

    @property
    def scene_names(self) -> list[str]:
        return list(dict.fromkeys(spec.scene for spec in self.stacks))

    @property
    def curve_names(self) -> list[str]:
        return list(dict.fromkeys(spec.curve for spec in self.stacks))


def full_design(scenes: Sequence[str] = SCENES, curves: Sequence[str] = CURVES
                ) -> tuple[StackSpec, ...]:
    """The full design, for ``scenes`` and ``curves``.

    * ``core``: every scene x every curve, 7 frames 2 EV apart, 8-bit (all methods);
    * ``ladder``: the other 11 ladders (3/5/7/9 frames x 1/2/3 EV) on two pairs, Desk
      with DoRF 0 and GoldenGate with DoRF 200 (a strong toe);
    * ``jpeg``: every scene with the EMoR mean curve, through JPEG quality 90;
    * ``16-bit``: three scenes (every scene when fewer than six) with the EMoR mean
      curve at 16 bits (hdrio only: OpenCV's and colour-hdri's Debevec take 8-bit);
    * ``linear``: the same scenes at 16 bits through a linear curve (a linear TIFF);
    * ``camera``: every scene with the EMoR mean curve through every camera of
      :data:`benchmarks.truth.camera.CAMERAS` (raw clip, white balance, colour matrix)
      at both noise levels (:data:`benchmarks.truth.camera.NOISE_LEVELS`).

    With user scenes the ladder pairs are the first and second scene.
    """
    from benchmarks.truth.camera import CAMERAS, NOISE_LEVELS

    frames, ev = REFERENCE_LADDER
    first, second = (("Desk", "GoldenGate") if set(scenes) >= {"Desk", "GoldenGate"}
                     else (scenes[0], scenes[min(1, len(scenes) - 1)]))
    typical = "emor-f0" if "emor-f0" in curves else curves[0]
    pairs = [(first, "dorf0" if "dorf0" in curves else curves[0]),
             (second, "dorf200" if "dorf200" in curves else curves[-1])]
    core = [StackSpec(s, c, frames, ev) for s in scenes for c in curves]
    ladder = [StackSpec(s, c, n, step, group="ladder") for s, c in pairs
              for n, step in LADDERS if (n, step) != REFERENCE_LADDER]
    jpeg = [StackSpec(s, typical, frames, ev, jpeg=True, group="jpeg") for s in scenes]
    deep_scenes = ("Desk", "GoldenGate", "StillLife") if set(scenes) >= set(SCENES) else scenes
    deep = [StackSpec(s, typical, frames, ev, bits=16, group="16-bit") for s in deep_scenes]
    linear = [StackSpec(s, "linear", frames, ev, bits=16, group="linear")
              for s in deep_scenes]
    camera = [StackSpec(s, typical, frames, ev, group="camera", camera=c, noise=n)
              for s in scenes for c in CAMERAS for n in NOISE_LEVELS]
    return tuple(core + ladder + jpeg + deep + linear + camera)


GROUPS = ("core", "ladder", "jpeg", "16-bit", "linear", "camera")


def full_config(scene_paths: dict[str, str] | None = None, width: int | None = 400,
                repeats: int = 3, methods: tuple[str, ...] | None = None,
                groups: tuple[str, ...] | None = None) -> Config:
    """The full run: 121 stacks (73 and 48 camera-like), scenes ~400 px wide (box factor
    2-3), 3 timed calls on the core stacks (docs/accuracy.md has the measured time).
    ``groups`` (of :data:`GROUPS`) keeps only those parts of the design.

    colour-hdri's dense least-squares solve (about 3 s a call whatever the image size)
    is most of the time, which is why the core is timed 3 times and the rest once.
    """
    scenes = tuple(scene_paths) if scene_paths else SCENES
    stacks = tuple(s for s in full_design(scenes) if groups is None or s.group in groups)
    return Config("full", stacks, width, repeats, dict(scene_paths or {}), methods)


def quick_config(scene_paths: dict[str, str] | None = None, width: int | None = 300,
                 repeats: int = 1, methods: tuple[str, ...] | None = None,
                 scenes: Sequence[str] = ("Desk", "GoldenGate"),
                 curves: Sequence[str] = ("dorf0", "dorf100")) -> Config:
    """A small subset: 2 scenes about 300 px wide, 2 curves, 7 frames 2 EV apart, 8-bit."""
    names = tuple(scene_paths)[:2] if scene_paths else tuple(scenes)
    frames, ev = REFERENCE_LADDER
    stacks = tuple(StackSpec(s, c, frames, ev) for s in names for c in curves)
    return Config("quick", stacks, width, repeats, dict(scene_paths or {}), methods)
