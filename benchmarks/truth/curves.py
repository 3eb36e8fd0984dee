"""Real camera response curves: DoRF (201 measured curves) and the EMoR mean curve.

Each curve maps sensor exposure ``X`` on [0, 1] to brightness on [0, 1]; brackets are
rendered through it (:func:`hdrio.tools.synthetic.tabulated_response`) and its exact inverse
is the truth that recovered responses are compared with.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from benchmarks.truth.scenes import data_folder
from hdrio.tools.synthetic import Response, tabulated_response

#: The fixed subset: evenly spread DoRF rows (120 and 200 have a strong toe, which
#: docs/method.md names as hdrio's known weak spot) and the EMoR mean curve ``f0``.
DORF_ROWS = (0, 50, 100, 120, 150, 200)
CURVES = (*(f"dorf{row}" for row in DORF_ROWS), "emor-f0")


@dataclass(frozen=True)
class Curve:
    """A tabulated camera response ``B = f(I)``, both rows on [0, 1], ``B`` non-decreasing."""

    name: str
    irradiance: np.ndarray
    brightness: np.ndarray

    @property
    def response(self) -> Response:
        """``f`` as a callable on [0, 1], for :func:`hdrio.tools.synthetic.render_brackets`."""
        return tabulated_response(self.irradiance, self.brightness)

    def log_inverse(self, codes: np.ndarray, code_max: int) -> np.ndarray:
        """``ln f^-1(z / code_max)``: the true inverse response at code values ``codes``.

        Code 0 is evaluated half a code up, and exposures are floored at 1e-12, so the
        result is finite everywhere.
        """
        level = np.maximum(np.asarray(codes, dtype=np.float64), 0.5) / code_max
        exposure = np.interp(level, self.brightness, self.irradiance)
        return np.log(np.maximum(exposure, 1e-12))

    def code_of(self, exposure: float) -> float:
        """``f(exposure)`` on [0, 1]: e.g. where 18 % grey lands when ``X = 0.18``."""
        return float(np.interp(exposure, self.irradiance, self.brightness))


@lru_cache(maxsize=1)
def _dorf() -> tuple[np.ndarray, np.ndarray]:
    import scipy.io

    table = scipy.io.loadmat(data_folder("crf_database") / "dorf" / "201_CRF_data.mat")
    return np.asarray(table["I"], np.float64), np.asarray(table["B"], np.float64)


@lru_cache(maxsize=1)
def emor_blocks() -> dict[str, np.ndarray]:
    """Every block of ``emor.txt``: ``E`` (irradiance), ``f0`` (mean), ``h(1)`` ... ``h(25)``."""
    blocks: dict[str, list[float]] = {}
    current: list[float] | None = None
    text = (data_folder("crf_database") / "emor" / "emor.txt").read_text()
    for line in text.splitlines():
        if "=" in line:
            name, _, rest = line.partition("=")
            current = blocks.setdefault(name.strip(), [])
            line = rest
        if current is not None:
            current.extend(float(value) for value in line.split())
    return {name: np.asarray(values) for name, values in blocks.items()}


def load_curve(name: str) -> Curve:
    """``dorfN`` (row N of DoRF's ``201_CRF_data.mat``), ``emor-f0`` (EMoR's mean curve)
    or ``linear`` (a linear sensor's codes: a linear TIFF from a raw converter)."""
    if name == "linear":
        return Curve(name, np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    if name.startswith("dorf"):
        irradiance, brightness = _dorf()
        row = int(name[4:])
        return Curve(name, irradiance[row], brightness[row])
    if name == "emor-f0":
        blocks = emor_blocks()
        return Curve(name, blocks["E"], np.clip(blocks["f0"], 0.0, 1.0))
    raise KeyError(f"unknown curve {name!r}: use dorf0..dorf200, emor-f0 or linear")
