"""Saturation policies: which observations near the top of the code range the merge drops.

A camera clips its *raw* channels at the sensor's white level, then white-balances and
mixes them with its colour matrix before the response curve. Once one raw channel has
clipped, every output channel of that pixel is wrong, and most of them are below the top
code: dropping only the codes at ``Z_max`` (``channel``) keeps those biased observations
and gives partly clipped highlights a false hue (the orange and yellow-green bands at a
clipped cloud's edge). On brackets rendered through such a camera
(:func:`hdrio.tools.synthetic.render_camera_brackets`: the 5D Mark II's matrix) the hue error
on clip-transition pixels reaches p99 90 degrees with ``channel``.

``auto`` (the default)
    each observation near the clip (a channel at or above its gate, another below its
    limit) is tested against the next shorter bracket (:mod:`hdrio.radiometry.cliptest`): dropped
    whole where its other channels disagree with it by more than noise (by more,
    where the stack does not show its channels mixed after the clip), else its clipped
    channels alone. In the shortest bracket, which has nothing to be tested
    against, whole where the stack shows its channels mixed after the clip
    (:func:`~hdrio.merge.clipping.channel_mixing` inside clips,
    :func:`~hdrio.merge.clipping.clip_interior`), else channel by channel.
``safe``
    an observation (one bracket at one pixel) counts only where *every* channel is
    below its limit; otherwise the whole observation is dropped.
``pixel`` (the tutorial's ``hdr.m``)
    any channel at ``Z_max`` drops the observation.
``channel``
    a channel at ``Z_max`` drops that channel alone: right only for a camera that does
    not mix its channels after the clip (the truth harness's renders).

A channel's *limit* (``auto``, ``safe``) is its white level, the code its clipped
observations pile up at (:func:`~hdrio.merge.clipping.white_levels`), less the noise
model's margin (:func:`~hdrio.merge.clipping.saturation_limits`). Whatever the policy, a
dropped observation is dropped from its bracket and every longer one.

Pixels dropped even from the shortest bracket (clipped in every bracket) take a neutral
lower bound in the kernel (:func:`hdrio.merge.kernel.merge_kernel`): every channel the
largest of the shortest bracket's estimates, so they carry no colour cast;
``--highlights reconstruct`` (:mod:`hdrio.merge.highlights`) estimates them from their
neighbours' colour instead.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass, replace

import numpy as np

from hdrio.merge.clipping import (
    MIXING_GRID_LIMIT,
    channel_mixing,
    clip_gates,
    clip_interior,
    saturation_limits,
    test_spreads,
    unexcluded,
)
from hdrio.radiometry.cliptest import (
    APART_SIGMAS,
    CLIP_SIGMAS,
    RULES,
    ClipTables,
    clip_tables,
    dropped_observations,
)
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import NoiseModel, noise_encoding
from hdrio.radiometry.noise_fit import fit_noise, noise_grid
from hdrio.stack import ExposureStack, every_channel, some_channel

SATURATION_POLICIES = ("auto", "safe", "channel", "pixel")

MIXING_SHIFT = 0.9
"""Spreads (:func:`hdrio.merge.clipping.channel_mixing`, inside clips) above which a stack
shows its channels mixed after the clip. Stacks that keep their channels apart measure
at most 0.41 (the truth harness's renders), memorial 0.39, canal (``alignment/``) 0.36,
but 0.83 once warped (the response's re-solve after alignment: resampling blends a
clip's edge), ``ghost/`` 0; the camera-like stacks (a real camera's matrix after the raw
clip) 0.93 to 111, but for CandleGlass's small glints and Desk through the D700 at
sensor noise (0.38-0.81), which say too little either way. At 1.0, CandleGlass through
the D700 and the ILCE-7 at low noise (0.93, 0.999) were tested as unmixed and their hue
error's p99 was 1.62x and 1.54x the clipped-observation oracle's; at 0.9, 0.99x and
0.97x. At 0.7 canal's warped re-solve left out its observations at the clip and its sky
edges' fringe grew from 12 pixels to 22 (tests/test_merge_cliptest.py)."""

LIMIT_SLACK = 2
"""Codes below the limits at which the mixing is measured too, the largest measure
counting. A limit is the white level less a noise margin
(:func:`~hdrio.merge.clipping.saturation_limits`) set by the noise fit at the top codes,
which a different sample of the same stack moves by a code or two; and a channel 1-2
codes under a limit that should have been lower reads as unclipped in the measure's
clean group, where a mixing camera's bent codes then hide the mixing. Frobisher re-saved
by OpenImageIO, its sample turned by each of the 8 EXIF orientations: 4.54, 0.81, 3.79,
0.86, 5.13, 5.41, 6.39, 0.84 at the limits alone (below :data:`MIXING_SHIFT` wherever
blue's came out 255, not 253-254), 5.21-8.88 now; the original frobisher 3.76-5.78, now
5.63-8.04. Stacks that keep their channels apart are where they were: canal 0.727,
memorial 0.39, ``ghost/`` 0, the truth harness's renders at most 0.53 (0.52); the
camera-like stacks' decisions and pixels the same."""


@dataclass(frozen=True)
class ClipPolicy:
    """What the merge drops near the clip, decided once from the stack (:func:`clip_policy`)
    and applied by every kernel that merges (:mod:`hdrio.merge.kernel`,
    :mod:`hdrio.merge.masked`, :mod:`hdrio.merge.uncertainty`) and by the Blender node.

    Attributes
    ----------
    limits
        ``(C,)`` int64: the first dropped code of each channel.
    gates
        ``(C,)`` int64: an observation with a channel at or above its gate is *near the
        clip*, and tested (``test``); ``limits`` when not given.
    rule
        ``channel`` (a channel at its limit is dropped alone), ``pixel`` (the whole
        observation), ``test`` (whole where it fails the clip test,
        :mod:`hdrio.radiometry.cliptest`, else the clipped channels alone).
    neutral
        A partly clipped observation of the shortest bracket is dropped whole, so the
        pixel takes the neutral lower bound (the pixel rule, and ``test`` on a stack that
        mixes its channels after the clip).
    tables
        The clip test's tables (``test``), else ``None``.
    spreads
        ``(P, C)`` (``test``): the spread of the stack's clean observations about the
        noise model (:func:`~hdrio.merge.clipping.test_spreads`), which the test allows.
    mixing
        :func:`~hdrio.merge.clipping.channel_mixing` inside clips, where measured.
    dropped
        The share of the sampled partly clipped observations (a channel at its limit,
        another below; brackets after the shortest) the test drops whole, where
        measured.
    """

    limits: np.ndarray
    gates: np.ndarray | None = None
    rule: str = "channel"
    neutral: bool = False
    tables: ClipTables | None = None
    spreads: np.ndarray | None = None
    mixing: float | None = None
    dropped: float | None = None

    def __eq__(self, other: object) -> bool:
        """The same decisions and tables (the arrays compared by value)."""
        if not isinstance(other, ClipPolicy):
            return NotImplemented
        return _same(self, other)

    __hash__ = None  # arrays inside

    @classmethod
    def at_top(cls, code_max: int, channels: int, rule: str = "channel") -> ClipPolicy:
        """``rule`` at the top code (the tutorial's ``pixel``, and ``channel``)."""
        return cls(np.full(channels, code_max, np.int64), rule=rule, neutral=rule == "pixel")

    @property
    def pixel_rule(self) -> bool:
        """Every partly clipped observation is dropped whole."""
        return self.rule == "pixel"

    def for_brackets(self, response: CameraResponse, exposures, noise: NoiseModel | None
                     ) -> ClipPolicy:
        """The same decisions (limits, gates, rule, neutral, spreads) with the clip
        test's tables for brackets of ``exposures`` (seconds, shortest first) through
        ``response``: what a front end whose exposures can be edited applies (the
        Blender node)."""
        if self.rule != "test":
            return self
        sigmas = CLIP_SIGMAS if self.neutral else APART_SIGMAS
        if noise is None:
            noise = NoiseModel.quantisation_only(response.channels)
        spreads = self.spreads
        if spreads is not None and np.shape(spreads)[0] != len(exposures):
            spreads = None  # measured on another bracket count: the noise model alone
        return replace(self, tables=clip_tables(response, exposures, noise, sigmas),
                       spreads=spreads)

    def kernel_args(self) -> tuple:
        """The policy as the compiled kernels take it: ``(limits, gates, rule, neutral,
        estimates, variances, sigmas squared)``, the tables ``(1, 1, 1)`` zeros when
        there is no test (:func:`hdrio.radiometry.cliptest.dropped_channels`)."""
        empty = np.zeros((1, 1, 1))
        tables = self.tables
        limits = np.ascontiguousarray(self.limits, dtype=np.int64)
        gates = limits if self.gates is None else np.ascontiguousarray(self.gates, np.int64)
        thresholds = np.zeros((1, limits.size))
        if tables is not None:
            spreads = np.ones(tables.estimates.shape[:2]) if self.spreads is None \
                else np.asarray(self.spreads, np.float64)
            thresholds = np.ascontiguousarray((tables.sigmas * spreads) ** 2)
        return (limits, gates, np.int64(RULES[self.rule]),
                bool(self.neutral), empty if tables is None else tables.estimates,
                empty if tables is None else tables.variances, thresholds)


def _same(a, b) -> bool:
    """Whether ``a`` and ``b`` hold the same values: dataclasses field by field, arrays
    element by element."""
    if is_dataclass(a) and type(a) is type(b):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in fields(a))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return a is not None and b is not None and np.array_equal(a, b)
    return a == b


class _Sample:
    """The pixels a policy is decided on: ``full``, the noise grid of ``codes`` (every
    pixel sampled), and ``grid``, those of them no bracket is excluded at."""

    def __init__(self, codes: np.ndarray, exclude: np.ndarray | None):
        self.codes = codes
        self.full = noise_grid(codes, MIXING_GRID_LIMIT)
        self.seen = unexcluded(codes.shape, exclude)
        self.grid = self.full if self.seen is None else self.full[:, self.seen]

    def mixing(self, response: CameraResponse, exposures, limits) -> float:
        """:func:`~hdrio.merge.clipping.channel_mixing` inside the sample's clips: the
        largest of it at ``limits`` and at each of the :data:`LIMIT_SLACK` codes below
        them."""
        interior = clip_interior(self.codes, limits, grid=self.full)
        interior = interior if self.seen is None else interior[:, self.seen]
        limits = np.asarray(limits, np.int64)
        return max(channel_mixing(self.grid, response, exposures,
                                  np.maximum(limits - slack, 1), interior)
                   for slack in range(LIMIT_SLACK + 1))


@dataclass(frozen=True, eq=False)  # found by identity (Survey.holds_for), never compared
class Survey:
    """What deciding a policy measures on one stack through one response, no pixel
    excluded: the noise model, the sample, the limits and (where something clips) the
    mixing. The response solve's filter (:func:`solve_filter`) measures them first; the
    policy the deghost stage decides (:func:`clip_policy`) reads them again where
    nothing changed in between (the same codes, exposures, response and encoding): on
    7 x 24 MP JPEGs that was a second noise fit, white-level search and mixing measure,
    0.35 s of a 4.1 s merge."""

    codes: np.ndarray
    exposures: tuple
    response: CameraResponse
    encoding: str
    noise: NoiseModel
    sample: _Sample
    limits: np.ndarray
    mixing: float | None

    def holds_for(self, codes: np.ndarray, exposures, response: CameraResponse,
                  encoding: str) -> bool:
        """Measured on these very codes (the same array, not warped since) and response,
        with these exposures and encoding."""
        return (codes is self.codes and response is self.response
                and encoding == self.encoding
                and tuple(float(t) for t in exposures) == self.exposures)


class Surveys:
    """The last :class:`Survey` of a merge (one per merge: the job's stages share it)."""

    def __init__(self) -> None:
        self.last: Survey | None = None

    def find(self, codes: np.ndarray, exposures, response: CameraResponse,
             encoding: str) -> Survey | None:
        """The last survey, where it :meth:`~Survey.holds_for` these; else ``None``."""
        last = self.last
        return last if last is not None and last.holds_for(codes, exposures, response,
                                                           encoding) else None


def clip_policy(policy: str, codes: np.ndarray, response: CameraResponse,
                noise: NoiseModel | None, exposures=None, *,
                exclude: np.ndarray | None = None, survey: Survey | None = None
                ) -> ClipPolicy:
    """``policy`` (:data:`SATURATION_POLICIES`) decided on ``codes`` ``(P, H, W, C)``.

    ``channel``, ``pixel``: at the top code. ``safe``: the pixel rule at the white levels
    less the noise margin (:func:`~hdrio.merge.clipping.saturation_limits`). ``auto``:
    the clip test at those limits (:mod:`hdrio.radiometry.cliptest`: at
    :data:`~hdrio.radiometry.cliptest.CLIP_SIGMAS` where the stack mixes its channels,
    :data:`~hdrio.radiometry.cliptest.APART_SIGMAS` where not), the shortest bracket's
    partly clipped observations dropped whole where
    :func:`~hdrio.merge.clipping.channel_mixing` (inside clips,
    :func:`~hdrio.merge.clipping.clip_interior`; the largest within :data:`LIMIT_SLACK`
    codes of the limits) exceeds :data:`MIXING_SHIFT`; without ``exposures``
    (seconds) or with one bracket, as ``safe``. ``noise`` ``None``: the codes' rounding alone.
    ``exclude`` (``(P, H, W)`` or ``(H, W)``, ``--mask`` and ``--exclude-color``): pixels
    of the sample where some bracket is excluded are left out of every measure
    (:func:`~hdrio.merge.clipping.unexcluded`). ``survey``: what :func:`solve_filter`
    measured on these codes, response and ``noise`` (:meth:`Surveys.find`), read
    instead of measured again.
    """
    if policy not in SATURATION_POLICIES:
        raise ValueError(f"saturation policy must be one of {SATURATION_POLICIES}, "
                         f"not {policy!r}")
    channels = codes.shape[-1]
    if policy in ("channel", "pixel"):
        return ClipPolicy.at_top(response.code_max, channels, policy)
    if noise is None:
        noise = NoiseModel.quantisation_only(channels)
    if survey is not None:
        sample, limits = survey.sample, survey.limits
    else:
        sample = _Sample(codes, exclude)
        limits = saturation_limits(codes, response, noise, sample.grid)
    if policy == "safe" or exposures is None or codes.shape[0] < 2:
        return ClipPolicy(limits, rule="pixel", neutral=True)
    grid = sample.grid
    clipped = some_channel(grid, np.greater_equal, limits)
    if not clipped.any():  # nothing clips: each channel dropped alone, nothing tested
        return ClipPolicy(limits)
    mixing = survey.mixing if survey is not None and survey.mixing is not None \
        else sample.mixing(response, exposures, limits)
    gates = clip_gates(response, grid, limits, exposures)
    neutral = bool(mixing > MIXING_SHIFT)
    tables = clip_tables(response, exposures, noise,
                         CLIP_SIGMAS if neutral else APART_SIGMAS)
    chosen = ClipPolicy(limits, gates, "test", neutral, tables,
                        test_spreads(grid, tables, gates), mixing)
    partly = clipped & ~every_channel(grid, np.greater_equal, limits)
    partly[0] = False
    dropped = (dropped_observations(grid, chosen) == (1 << channels) - 1) & partly
    share = float(dropped.sum() / partly.sum()) if partly.any() else 0.0
    return replace(chosen, dropped=share)


@dataclass(frozen=True)
class SolveFilter:
    """The observations a response solve leaves out whole where the stack mixes its
    channels after the clip (:func:`solve_filter`): a channel at or above its limit, or
    (after the shortest bracket) the next shorter bracket's code of some channel at or
    above its ``reach``, which says the channel reaches its limit here.

    Called with codes ``(P, n, C)``, shortest bracket first; returns ``(P, n)`` bool.
    """

    limits: np.ndarray
    reach: np.ndarray
    """``(P, C)``: for bracket ``j >= 1``, the least code of bracket ``j - 1`` whose
    exposure times the exposure ratio is the limit's, ``f^-1(y) dt_j / dt_{j-1} >=
    f^-1(limit)``; row 0 past every code."""

    def __call__(self, codes: np.ndarray) -> np.ndarray:
        out = np.any(codes >= self.limits, axis=-1)
        out[1:] |= np.any(codes[:-1] >= self.reach[1:, None, :], axis=-1)
        return out

    def __repr__(self) -> str:
        return f"limits {', '.join(str(int(v)) for v in self.limits)} and their reach"


def solve_filter(policy: str, stack: ExposureStack, response: CameraResponse, *,
                 exclude: np.ndarray | None = None, surveys: Surveys | None = None
                 ) -> SolveFilter | None:
    """The observations the response solve leaves out (``dropped`` of
    :func:`hdrio.response.debevec1997.response_Debevec1997`), or ``None`` to keep the
    solve as it was.

    Where the merge drops partly clipped observations whole, the solve should not fit
    the curve to them: ``safe`` always, and ``auto`` on a stack that shows its channels
    mixed after the clip (:func:`~hdrio.merge.clipping.channel_mixing` inside clips
    above :data:`MIXING_SHIFT`, measured with ``response``, the solve without the filter),
    where they are biased in every channel: on camera-like brackets through the 5D Mark
    II's matrix the green curve of a solve that kept them fell 0.2 in ``ln`` at the top
    codes, and the hue error's p99 on clip-transition pixels tripled. A raw channel that clipped can
    leave every output channel below its limit (a colour matrix's positive
    off-diagonal terms), so the observations that the next shorter bracket says reach a
    limit go too (:attr:`SolveFilter.reach`, by ``response``: the red curve was 5 % off
    at the top codes without them). Elsewhere a partly clipped observation's unclipped
    channels are as good as any, and the solve keeps them. ``exclude``: the solve's
    ``(H, W)`` pixels never sampled, left out of what decides it too. ``surveys``: where
    nothing is excluded, what was measured is kept there (:class:`Survey`).
    """
    if policy not in ("auto", "safe") or stack.count < 2:
        return None
    encoding = noise_encoding(stack.files, stack.code_max)
    noise = fit_noise(stack.codes, stack.exposures, response, encoding=encoding,
                      exclude=exclude)
    sample = _Sample(stack.codes, exclude)
    limits = saturation_limits(stack.codes, response, noise, sample.grid)
    # clip_policy's neutral, without its test's tables
    mixing = sample.mixing(response, stack.exposures, limits) \
        if policy == "auto" and np.any(sample.grid >= limits) else None
    if surveys is not None and exclude is None:
        surveys.last = Survey(stack.codes, tuple(float(t) for t in stack.exposures),
                              response, encoding, noise, sample, limits, mixing)
    if policy == "auto" and not (mixing is not None and mixing > MIXING_SHIFT):
        return None
    X = np.exp(response.log_inverse)
    times = np.asarray(stack.exposures, dtype=np.float64)
    reach = np.full((stack.count, X.shape[1]), X.shape[0], dtype=np.int64)
    for j in range(1, stack.count):
        for c in range(X.shape[1]):
            level = X[limits[c], c] * times[j - 1] / times[j]
            reach[j, c] = np.searchsorted(X[:, c], level, side="left")
    return SolveFilter(limits, reach)
