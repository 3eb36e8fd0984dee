"""The clip test: which observations a clip corrupted, one pixel and one bracket at a time.

A camera clips its *raw* channels, then white-balances them and mixes them with its
colour matrix; a JPEG encoder then shares chroma between neighbouring pixels (4:2:0) and
8 x 8 blocks. Once a channel has clipped, the pixel's *other* channels are off too, most
of them below the top code. Which observations that happened to shows in the stack
itself: the observation disagrees with the next shorter bracket's by more than noise.

An observation (bracket ``j >= 1`` at one pixel) *near the clip* is *tested*: some
channel is below its limit (:func:`hdrio.merge.clipping.white_levels` less the noise
margin), and some channel is at or above its gate
(:func:`hdrio.merge.clipping.clip_gates`: a raw channel that clipped can leave its
own output channel a little below the top code, and a JPEG's ringing a clipped one's),
or is below its limit where the next shorter bracket is at it.
Each channel below its limit is compared with the next shorter bracket's estimate of
the same radiance,

    (x_j - x_{j-1})^2 > K^2 s^2 (var x_j + var x_{j-1}),

``x_j = f^-1(z_j) / dt_j`` (relative radiance) and the variances the noise model's
(:func:`hdrio.radiometry.noise.observation_variance`), times the spread the stack's clean
observations show about them (:func:`hdrio.merge.clipping.test_spreads`: a noise model
that leaves noise out, a response that is a few percent off, must not make every
partly clipped observation look corrupted). Where a channel disagrees by more than
:data:`CLIP_SIGMAS` such standard deviations, or is at its limit in the shorter bracket
and not in this one, or the shorter bracket's estimate is above :data:`REACH` times
the radiance at which this one clips (a clip only grows with exposure: a JPEG's
ringing, or a misregistered edge, put a clipped channel's code below its limit), the whole
observation is dropped (from its bracket and, as every dropped code, from every longer
one): a clip reached the pixel. An observation with no channel near its clip is never
tested (a stack where nothing clips is merged as before); one with every channel at its
limit is dropped channel by channel, which is the same. An observation below its limit
where the shorter bracket is at it fails wherever its codes are, far from any gate: the
longer exposure must have clipped there, so it saw something else (a mover, a
misregistered edge). The resets drop only that channel of it; kept, its other channels
stood beside the shorter brackets' estimate of the clipped one: on the hand-held canal
stack the flapping laundry's edge read (30, 28) in red and green from the longest frame
and 442 in blue from the shortest, a blue speck (isolated coloured pixels of the default
preview, 56 before, 26 after).

How far is too far depends on what the stack shows: :data:`CLIP_SIGMAS` where it
mixes its channels after the clip (``neutral``), :data:`APART_SIGMAS` where it does not
(the test drops an observation on the next shorter bracket's word, and where the clips
leave the other channels as they were that bracket is the worse of the two as often).

The shortest bracket has no shorter one to be tested against: a partly clipped
observation there is dropped whole where the stack shows its channels mixed after the
clip (``neutral``; :func:`hdrio.merge.clipping.channel_mixing`), so that the pixel takes
the neutral lower bound, and kept channel by channel otherwise.

The test is a function of the two brackets' codes at one pixel, through tables of
``x_j`` and ``var x_j`` per code: the merge kernel (:mod:`hdrio.merge.kernel`), the
masked re-merge (:mod:`hdrio.merge.masked`), the uncertainty layer and the Blender
add-on's node graph apply the same test from the same tables (:class:`ClipTables`);
deghosting's consistency test (:mod:`hdrio.align.consistency`) passes over what it
drops where the stack mixes its channels after the clip. (It sits in radiometry, below
both, because alignment and the merge never import each other.)

:func:`dropped_channels` is compiled into those modules' cached kernels: numba's cache
checks only each kernel's own file, so after editing this one in a checkout, delete
``hdrio/merge/__pycache__/*.nb*`` and ``hdrio/align/__pycache__/*.nb*`` (an install
writes every file anew, which does it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from hdrio.jit import INNER
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import NoiseModel, observation_variance
from hdrio.stack import exposure_columns

CLIP_SIGMAS = 2.0
"""Standard deviations of disagreement with the next shorter bracket that mark a partly
clipped observation as corrupted by its clip, where the stack shows its channels mixed
after the clip (``neutral``): there most partly clipped observations are (84 % of them on
GoldenGate through the D700's matrix), and a clean one dropped costs less than a biased
one kept. On GoldenGate through the 5D Mark II at 200 px the hue error's p99 on
clip-transition pixels is 10.6 degrees with 3, 9.5 with 2, 9.1 for the oracle."""

APART_SIGMAS = 6.0
"""The same where the stack does not show it: only a gross disagreement (a JPEG's
ringing and chroma at a clip's edge, a misregistered edge) marks an observation there.
On the truth harness's renders, whose clips leave the other channels as they were, 3
standard deviations dropped 11-30 % of the partly clipped JPEG observations and cost up
to 0.08 points of median error (GoldenGate 2.160 % to 2.237 %), 6 cost 0.001; on the
hand-held canal JPEGs (no mixing shown) 6 leaves 12 of 3186 sky-edge pixels more than
10 degrees off the best bracket's hue, 4 leaves 9 (335 before the test; 9 at 6 with
:data:`REACH`)."""

REACH = 1.25
"""A channel below its limit in bracket ``j`` where the shorter bracket's estimate is
above this factor times the radiance at which ``j`` clips (``x_j(limit)``) fails the
test whatever the variances say: the longer exposure must have clipped there, so its
code was bent (a clip's edge, JPEG's ringing, a misregistered edge). Near the top codes
a response's slope makes the variances too wide to tell: on the hand-held canal stack
a sky pixel read (200, 225, 247) in the 1/4 s frame and (254, 255, 249) in the 1 s one,
whose blue, kept, put a yellow speck on the sky's edge. The margin covers a response a
few percent off at its top."""

RULES = {"channel": 0, "pixel": 1, "test": 2}
"""How a partly clipped observation is dropped: its clipped channels alone (``channel``),
whole (``pixel``), or as the clip test finds (``test``)."""


@dataclass(frozen=True)
class ClipTables:
    """What the test reads, per bracket ``j``, channel ``c`` and code ``z``.

    Attributes
    ----------
    estimates
        ``(P, C, levels)`` float64: ``x_j(z) = f^-1(z) / dt_j`` (relative radiance).
    variances
        ``(P, C, levels)`` float64: ``var x_j(z)`` (relative radiance squared).
    sigmas
        :data:`CLIP_SIGMAS` or :data:`APART_SIGMAS`: the disagreement that fails the
        test, in standard deviations.
    """

    estimates: np.ndarray
    variances: np.ndarray
    sigmas: float = CLIP_SIGMAS


def clip_tables(response: CameraResponse, exposures, noise: NoiseModel,
                sigmas: float = CLIP_SIGMAS) -> ClipTables:
    """The test's tables for brackets of ``exposures`` (seconds, shortest first) through
    ``response``, with ``noise``'s variances; ``sigmas``: :data:`CLIP_SIGMAS` where the
    stack mixes its channels after the clip, else :data:`APART_SIGMAS`
    (:func:`hdrio.merge.saturation.clip_policy` chooses)."""
    with np.errstate(over="ignore"):
        estimates = (np.exp(response.log_inverse).T[None]
                     / exposure_columns(exposures)[:, :, None])
    variances = observation_variance(response, exposures, noise)
    return ClipTables(np.ascontiguousarray(estimates, dtype=np.float64),
                      np.ascontiguousarray(variances, dtype=np.float64), float(sigmas))


@njit(inline="always", **INNER)
def dropped_channels(longer, shorter, base, j, k, limits, gates, rule, neutral, estimates,
                     variances, threshold, loosen):  # pragma: no cover - compiled
    """The channels of bracket ``j``'s observation at the pixel whose channels start at
    ``longer[base]`` that the policy drops besides those at or above their limits, as
    a bit set (bit ``c``: channel ``c``; every bit: the whole observation); ``shorter``
    holds bracket ``k``'s codes at the same place (``k < j``: the bracket it is tested
    against, the next shorter one kept, ``j - 1`` but where that one is masked out;
    read only for ``j >= 1``).

    The policy's parts are :meth:`hdrio.merge.saturation.ClipPolicy.kernel_args`,
    ``(limits, gates, rule, neutral, estimates, variances, thresholds)``, the thresholds
    ``(P, C)`` the squared disagreement each pair of brackets and channel allows, in
    variances; ``loosen`` divides them (a resampled bracket's factor, below 1:
    :func:`hdrio.merge.masked.remerge_masked`; 1 elsewhere, which leaves them exactly as
    they are). A scalar, not a per-pixel copy of the thresholds: writing one for every
    observation took half of the masked re-merge's time. A kernel unpacks that tuple
    once, outside its loops, and passes the parts: the tuple handed to a function called
    per pixel costs an atomic reference count per array and call, which the threads then
    contend for (6 s of a 24 MP merge's 7).
    """
    channels = limits.size
    whole = (1 << channels) - 1
    clipped = 0
    near = 0
    for c in range(channels):
        z = longer[base + c]
        clipped += z >= limits[c]
        near += z >= gates[c]
        # Below its limit where the shorter bracket is at it: this one must have clipped.
        near += j > 0 and z < limits[c] and shorter[base + c] >= limits[c]
    if rule == 0 or near == 0 or clipped == channels:  # each channel on its own
        return 0
    if rule == 1 or j == 0:  # the pixel rule; the shortest bracket: nothing to test
        return whole if clipped > 0 and (rule == 1 or neutral) else 0
    for c in range(channels):
        z = longer[base + c]
        y = shorter[base + c]
        if z >= limits[c]:
            continue
        shorter_x = estimates[k, c, y]
        d = estimates[j, c, z] - shorter_x
        allowed = threshold[j, c] / loosen
        if (y >= limits[c] or shorter_x > REACH * estimates[j, c, limits[c]]
                or d * d > allowed * (variances[j, c, z] + variances[k, c, y])):
            return whole
    return 0


@njit(**INNER)
def dropped_channels_call(longer, shorter, base, j, k, limits, gates, rule, neutral,
                          estimates, variances, threshold):  # pragma: no cover - compiled
    """:func:`dropped_channels` as a function of its own, compiled once and called, not
    inlined, by the kernels that ask once per sample (deghosting's test,
    :func:`dropped_observations`): inlined into deghosting's test it cost a first run 4 s
    of compiling. (The merge's kernels, which ask per pixel on every thread, inline
    :func:`dropped_channels`: a call passes its arrays with a reference count each, which
    the threads contend for.)"""
    return dropped_channels(longer, shorter, base, j, k, limits, gates, rule, neutral,
                            estimates, variances, threshold, 1.0)


def untested(code_max: int, channels: int) -> tuple:
    """The policy's parts (:func:`dropped_channels`) of one that drops nothing whole: each
    channel alone at the top code, no test."""
    limits = np.full(channels, code_max, np.int64)
    return (limits, limits, np.int64(0), False, np.zeros((1, 1, 1)), np.zeros((1, 1, 1)),
            np.zeros((1, channels)))


@njit(cache=True, nogil=True)
def _flag_grid(codes, policy, out):  # pragma: no cover - compiled
    count, n, channels = codes.shape
    limits, gates, rule, neutral, estimates, variances, threshold = policy
    for j in range(count):
        previous = max(j - 1, 0)
        for i in range(n):
            out[j, i] = dropped_channels_call(codes[j, i], codes[previous, i], 0, j,
                                              previous, limits, gates, rule, neutral,
                                              estimates, variances, threshold)


def dropped_observations(codes: np.ndarray, policy) -> np.ndarray:
    """``(P, n)`` uint8: :func:`dropped_channels` of every observation of ``codes``
    ``(P, n, C)`` (a sample of pixels, shortest bracket first) under ``policy``
    (:class:`hdrio.merge.saturation.ClipPolicy`); ``2^C - 1`` where it is dropped whole."""
    codes = np.ascontiguousarray(codes)
    out = np.zeros(codes.shape[:2], dtype=np.uint8)
    _flag_grid(codes, policy.kernel_args(), out)
    return out
