"""Measure the colour-management numbers quoted in docs/colour.md.

    python -m benchmarks.colour

Prints: OCIO conversions against colour-science, the ACEScg round trip of a merge, the
exported response through oiiotool against hdrio, and the frobisher EXIF calibration
agreement between exposures. Needs ``../shared/data`` and ``oiiotool`` beside python.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import colour
import numpy as np

from benchmarks.truth.scenes import data_folder
from hdrio.cms import spaces
from hdrio.cms.calibration import Calibration
from hdrio.cms.lut import export_response
from hdrio.io.brackets import read_codes
from hdrio.io.images import read_image
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_files
from hdrio.radiometry.luminance import luminance

TARGETS = (("ACEScg", "ACEScg"), ("ACES2065-1", "ACES2065-1"),
           ("lin_p3d65_scene", "Display P3"), ("lin_rec2020_scene", "ITU-R BT.2020"),
           ("lin_adobergb_scene", "Adobe RGB (1998)"))


def _read(path: Path) -> np.ndarray:
    return read_image(path)[0].astype(np.float64)


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b) / np.max(np.abs(b), axis=-1, keepdims=True)))


def conversions() -> None:
    rgb = np.random.default_rng(0).uniform(0.0, 100.0, (100_000, 3))
    print("OCIO (built-in cg-config) against colour-science (Bradford), from lin_rec709:")
    for name, theirs in TARGETS:
        ours = spaces.convert(rgb, "lin_rec709_scene", name)
        expected = colour.RGB_to_RGB(rgb, "ITU-R BT.709", theirs,
                                     chromatic_adaptation_transform="Bradford")
        print(f"  {name:20s} max relative error {_relative(ours, expected):.1e}")


def acescg_round_trip(out: Path) -> None:
    files = sorted((data_folder("frobisher_001")).glob("IMG_26*.jpg"))
    for pixel_type in ("float", "half"):
        merge_files(files, out / "aces.exr", pixel_type=pixel_type,
                    options=MergeOptions(output_space="ACEScg"))
        merge_files(files, out / "rec709.exr", pixel_type=pixel_type)
        back = colour.RGB_to_RGB(_read(out / "aces.exr"), "ACEScg", "ITU-R BT.709",
                                 chromatic_adaptation_transform="Bradford")
        reference = _read(out / "rec709.exr")
        error = np.abs(back - reference) / np.max(np.abs(reference), axis=-1, keepdims=True)
        print(f"frobisher ACEScg EXR -> Rec.709 vs Rec.709 EXR ({pixel_type}): relative "
              f"error max {error.max():.1e}, 99.9 % {np.percentile(error, 99.9):.1e}, "
              f"median {np.median(error):.1e}")


def response_through_oiiotool(out: Path) -> None:
    folder = data_folder("memorial_debevec")
    brackets = sorted(folder.glob("memorial00*.png"))
    result = merge_files(brackets, out / "memorial.exr", exposures_from=folder / "exposures.csv",
                         options=MergeOptions(exclude_colour=(0, 0, 255)))
    tool = Path(sys.executable).with_name("oiiotool")
    for lut_format in ("spi1d", "clf"):
        _, config = export_response(out / "memorial.exr", out, "memorial", lut_format)
        worst = 0.0
        for bracket in brackets:
            target = out / "linear.exr"
            subprocess.run([str(tool), "--colorconfig", str(config), str(bracket),
                            "--colorconvert", "memorial", "lin_rec709_scene", "-d", "float",
                            "-o", str(target)], check=True, capture_output=True)
            ours = result.response.linearise(read_codes(bracket)[0])
            worst = max(worst, float(np.max(np.abs(_read(target) - ours) / ours)))
        print(f"memorial response via oiiotool ({lut_format}), 16 brackets: max relative "
              f"error {worst:.1e}")


def frobisher_calibration(out: Path) -> None:
    files = sorted(data_folder("frobisher_001").glob("IMG_26*.jpg"))
    result = merge_files(files, out / "frobisher.exr", pixel_type="float",
                         options=MergeOptions(calibration=Calibration()))
    stack, scale = result.stack, result.colour.luminance_scale
    merged = luminance(result.radiance)
    print(f"frobisher EXIF calibration: {scale:.4g} cd/m^2 per relative unit; merged "
          f"median {np.median(merged):.3g} cd/m^2")
    singles = []
    for j, t in enumerate(stack.exposures):
        good = np.all((stack.codes[j] > 25) & (stack.codes[j] < 230), axis=-1)
        L = scale * luminance(result.response.linearise(stack.codes[j])) / t
        singles.append((good, L))
        print(f"  {Path(stack.files[j]).name} ({t:g} s): median single-exposure / merged "
              f"{np.median(L[good] / merged[good]):.4f} over {good.sum()} pixels")
    for (a, La), (b, Lb), j in zip(singles, singles[1:], range(len(singles))):
        both = a & b
        print(f"  bracket {j + 1} / bracket {j}: median {np.median(Lb[both] / La[both]):.4f} "
              f"over {both.sum()} pixels")


def main() -> int:
    conversions()
    with tempfile.TemporaryDirectory() as temp:
        out = Path(temp)
        acescg_round_trip(out)
        response_through_oiiotool(out)
        frobisher_calibration(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
