"""The methods compared: hdrio variants, OpenCV and colour-hdri, run on identical stacks.

Every method takes a rendered :class:`~benchmarks.truth.stacks.Stack` (RGB codes, times
in seconds) and returns radiance ``(H, W, 3)`` RGB plus the recovered inverse response
as ``ln f^-1`` per code ``(levels, 3)`` RGB. Peers are imported lazily; a missing one is
skipped with a note. OpenCV's and colour-hdri's Debevec implementations take 8-bit
input only (256-entry responses), so they run on 8-bit stacks only.
"""

from __future__ import annotations

import importlib.util
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from benchmarks.truth.report import CLIP_ORACLE, NOISE_ORACLE
from benchmarks.truth.stacks import READ_NOISE, SHOT_NOISE, Stack
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_stack
from hdrio.merge.methods import MERGE_METHODS
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import QUANTISATION, NoiseModel, noise_encoding
from hdrio.radiometry.noise_fit import fit_noise
from hdrio.stack import ExposureStack


@dataclass(frozen=True)
class MethodOutput:
    """``radiance`` RGB ``(H, W, 3)`` (any positive scale) and ``log_inverse`` ``(L, 3)``;
    ``saturation``: what hdrio's saturation policy decided, for the report."""

    radiance: np.ndarray
    log_inverse: np.ndarray | None
    saturation: dict | None = None


@dataclass(frozen=True)
class Method:
    """A named way of turning a stack into radiance.

    Attributes
    ----------
    name
        Label in the reports.
    kind
        ``hdrio``, ``peer`` or ``reference`` (the oracle: not a competitor).
    run
        The call that is timed and whose memory is measured.
    bits
        Bit depths the method accepts.
    requires
        Module that must be importable, or ``None``.
    description
        One line for the report.
    """

    name: str
    kind: str
    run: Callable[[Stack], MethodOutput]
    bits: tuple[int, ...] = (8, 16)
    requires: str | None = None
    description: str = ""
    settings: dict = field(default_factory=dict)
    clip_truth: bool = False
    """Runs only on stacks that know which observations clipped in raw (``camera``)."""

    def missing(self) -> str | None:
        """Why the method cannot run here (its module is not installed), else ``None``."""
        if self.requires and importlib.util.find_spec(self.requires) is None:
            return f"{self.requires} is not installed (pip install .[bench])"
        return None

    def supports(self, stack: Stack) -> bool:
        """Whether the method accepts the stack's bit depth (and knows its clip)."""
        return stack.spec.bits in self.bits and (not self.clip_truth
                                                 or stack.clipped is not None)


def exposure_stack(stack: Stack) -> ExposureStack:
    """The rendered codes as hdrio sees them, named as a user's files would be (``.jpg``
    for the JPEG stacks: the noise model floors a JPEG's code noise)."""
    suffix = ".jpg" if stack.spec.jpeg else ".png"
    return ExposureStack.from_arrays(stack.codes, stack.times, code_max=stack.code_max,
                                     files=[f"frame{j}{suffix}" for j in range(len(stack.times))])


def _hdrio(options: MergeOptions) -> Callable[[Stack], MethodOutput]:
    def run(stack: Stack) -> MethodOutput:
        result = merge_stack(exposure_stack(stack), options)
        policy = getattr(result.statistics, "policy", None)
        saturation = None if policy is None else {
            "rule": policy.rule, "neutral": bool(policy.neutral), "mixing": policy.mixing,
            "dropped": policy.dropped, "limits": [int(v) for v in policy.limits]}
        return MethodOutput(result.radiance, result.response.log_inverse, saturation)

    return run


def true_response(stack: Stack) -> tuple[CameraResponse, float]:
    """The true ``g`` as a :class:`CameraResponse` (``g(mid) = 0``), and the sensor exposure
    at the middle code (the unit of the response's relative ``X``)."""
    g = stack.curve.log_inverse(np.arange(stack.code_max + 1), stack.code_max)
    middle = g[(stack.code_max + 1) // 2]
    table = np.repeat((g - middle)[:, None], 3, axis=1)
    return (CameraResponse(table, stack.code_max, np.ones(table.shape, dtype=bool),
                           method="truth"), float(np.exp(middle)))


def true_noise(stack: Stack) -> NoiseModel:
    """The renderer's noise (:func:`hdrio.tools.synthetic.render_brackets`) in the response's
    relative units: shot and read noise of the sensor, rounding of the codes."""
    _, unit = true_response(stack)
    return NoiseModel(np.full(3, SHOT_NOISE / unit), np.full(3, READ_NOISE**2 / unit**2),
                      np.full(3, QUANTISATION), source="truth")


def _oracle(stack: Stack) -> MethodOutput:
    """hdrio's default merge given the true response: the error left to the merge alone."""
    response, _ = true_response(stack)
    exposures = exposure_stack(stack)
    radiance, _ = MERGE_METHODS[MergeOptions().merge](
        exposures, response, MergeOptions().weighting,
        noise=fit_noise(exposures.codes, exposures.exposures, response,
                        encoding=noise_encoding(exposures.files, exposures.code_max)))
    return MethodOutput(radiance, response.log_inverse)


def _oracle_noise_aware(stack: Stack) -> MethodOutput:
    """True response, true noise model, inverse-variance weights: the bound to approach."""
    response, _ = true_response(stack)
    radiance, _ = MERGE_METHODS["inverse-variance"](exposure_stack(stack), response,
                                                    noise=true_noise(stack))
    return MethodOutput(radiance, response.log_inverse)


def _oracle_Poisson(stack: Stack) -> MethodOutput:
    """True response, the Poisson estimator (sum of linear values over sum of times)."""
    response, _ = true_response(stack)
    radiance, _ = MERGE_METHODS["Poisson"](exposure_stack(stack), response,
                                           noise=true_noise(stack))
    return MethodOutput(radiance, response.log_inverse)


def _oracle_clipped(stack: Stack) -> MethodOutput:
    """Exactly the raw-clipped observations dropped (whole), the true response, weights
    by exposure (:mod:`benchmarks.truth.camera`)."""
    from benchmarks.truth.camera import oracle_codes

    response, _ = true_response(stack)
    codes = oracle_codes(stack.codes, stack.clipped, stack.code_max)
    exposures = ExposureStack.from_arrays(codes, stack.times, code_max=stack.code_max,
                                          files=[f"frame{j}.png" for j in range(codes.shape[0])])
    radiance, _ = MERGE_METHODS["Poisson"](exposures, response, saturation="channel",
                                           noise=true_noise(stack))
    return MethodOutput(radiance, response.log_inverse)


def _opencv_inputs(stack: Stack) -> tuple[list[np.ndarray], np.ndarray]:
    images = [np.ascontiguousarray(frame[..., ::-1]) for frame in stack.codes]  # RGB -> BGR
    return images, np.asarray(stack.times, dtype=np.float32)


def _opencv_output(radiance: np.ndarray, response: np.ndarray) -> MethodOutput:
    with np.errstate(divide="ignore", invalid="ignore"):
        log_inverse = np.log(response.reshape(-1, 3)[:, ::-1].astype(np.float64))
    return MethodOutput(radiance[..., ::-1], log_inverse)


def _opencv_debevec(stack: Stack) -> MethodOutput:
    import cv2

    images, times = _opencv_inputs(stack)
    response = cv2.createCalibrateDebevec().process(images, times)
    return _opencv_output(cv2.createMergeDebevec().process(images, times, response), response)


def _opencv_robertson(stack: Stack) -> MethodOutput:
    import cv2

    images, times = _opencv_inputs(stack)
    response = cv2.createCalibrateRobertson().process(images, times)
    radiance = cv2.createMergeRobertson().process(images, times, response)
    return _opencv_output(radiance, response)


def _colour_hdri(stack: Stack) -> MethodOutput:
    """colour-hdri's Debevec 1997: Grossberg 2003 samples, lambda 30, its own merge.

    Its exposure is ``1 / average_luminance(N, t, S) = t S / (12.5 N^2)``; with
    ``N = 1`` and ``S = 100`` that is ``8 t``, proportional to the exposure time.
    """
    import colour_hdri

    images = colour_hdri.ImageStack()
    for frame, time in zip(stack.codes, stack.times):  # shortest first, as it expects
        metadata = colour_hdri.Metadata(f_number=1.0, exposure_time=float(time), iso=100.0)
        images.append(colour_hdri.Image(data=frame / float(stack.code_max), metadata=metadata))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "values <= 0", on every bracket with black codes
        crfs = colour_hdri.camera_response_functions_Debevec1997(images)
        radiance = colour_hdri.image_stack_to_HDRI(images, camera_response_functions=crfs)
    with np.errstate(divide="ignore", invalid="ignore"):  # its polynomial ends can dip <= 0
        return MethodOutput(np.asarray(radiance), np.log(np.asarray(crfs, dtype=np.float64)))


HDRIO_VARIANTS: dict[str, tuple[MergeOptions, str]] = {
    "hdrio default": (MergeOptions(), "Debevec response (triangle weights, 1000 stratified "
                      "samples, lambda 50), inverse-variance merge with the fitted noise "
                      "model, per-channel saturation"),
    "hdrio log": (MergeOptions(merge="log"), "default response, the tutorial's log-domain "
                  "triangle-weighted merge (the default before the noise model)"),
    "hdrio Poisson": (MergeOptions(merge="Poisson"), "default response, Poisson estimator"),
    "hdrio Robertson2003": (MergeOptions(response="Robertson2003"),
                            "Debevec's response refined by maximum likelihood with the noise "
                            "model (Robertson et al. 2003), the default merge"),
    "hdrio tutorial": (MergeOptions(weighting="tutorial-hat", sampling="tutorial",
                                    merge="log", saturation="pixel"),
                       "the tutorial's hat weights, sample grid and per-pixel saturation"),
    "hdrio pixel saturation": (MergeOptions(saturation="pixel"),
                               "default with the tutorial's per-pixel saturation policy"),
    "hdrio channel saturation": (MergeOptions(saturation="channel"),
                                 "default with the per-channel saturation policy (the "
                                 "default before the safe policy)"),
    "hdrio safe saturation": (MergeOptions(saturation="safe"),
                              "default with the safe saturation policy (every channel "
                              "below its white level less the noise's margin)"),
    "hdrio linear": (MergeOptions(merge="linear"), "default response, triangle-weighted "
                     "merge in the linear domain"),
    "hdrio lambda 10": (MergeOptions(smoothing=10.0), "default with lambda 10"),
    "hdrio lambda 200": (MergeOptions(smoothing=200.0), "default with lambda 200"),
    "hdrio 300 samples": (MergeOptions(samples=300), "default with 300 samples"),
    "hdrio 3000 samples": (MergeOptions(samples=3000), "default with 3000 samples"),
}


def all_methods() -> list[Method]:
    """Every method, hdrio's first; the reference oracle last."""
    methods = [Method(name, "hdrio", _hdrio(options), description=text,
                      settings={k: v for k, v in vars(options).items() if v is not None})
               for name, (options, text) in HDRIO_VARIANTS.items()]
    methods += [
        Method("OpenCV Debevec", "peer", _opencv_debevec, (8,), "cv2",
               "cv2.createCalibrateDebevec() (70 samples, lambda 10) + createMergeDebevec()"),
        Method("OpenCV Robertson", "peer", _opencv_robertson, (8,), "cv2",
               "cv2.createCalibrateRobertson() (30 iterations) + createMergeRobertson()"),
        Method("colour-hdri Debevec", "peer", _colour_hdri, (8,), "colour_hdri",
               "camera_response_functions_Debevec1997 + image_stack_to_HDRI"),
        Method("oracle (true response)", "reference", _oracle,
               description="hdrio's default merge with the true response: merge error only"),
        Method(NOISE_ORACLE, "reference", _oracle_noise_aware,
               description="true response, true noise model, inverse-variance weights: the "
                           "bound hdrio is measured against"),
        Method("oracle Poisson", "reference", _oracle_Poisson,
               description="true response, Poisson estimator (no noise parameters)"),
        Method(CLIP_ORACLE, "reference", _oracle_clipped, (8,), clip_truth=True,
               description="camera-like stacks: exactly the raw-clipped observations "
                           "dropped, true response, weights by exposure"),
    ]
    return methods


def select_methods(names: list[str] | None = None) -> list[Method]:
    """The methods called ``names`` (case-insensitive), or all of them."""
    methods = all_methods()
    if not names:
        return methods
    wanted = {name.strip().lower() for name in names}
    chosen = [m for m in methods if m.name.lower() in wanted]
    unknown = wanted - {m.name.lower() for m in chosen}
    if unknown:
        raise KeyError(f"unknown methods {sorted(unknown)}; known: {[m.name for m in methods]}")
    return chosen
