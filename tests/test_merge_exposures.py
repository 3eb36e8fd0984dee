"""Exposures from the data (hdrio.merge.exposures, --exposures-from-data): a bracket whose
EXIF exposure is off is named, and the data's estimate recovers it."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from hdrio.io.write import write_image
from hdrio.merge.exposures import anchor_Theil_Sen
from hdrio.pipeline import MergeOptions, merge_stack
from hdrio.stack import ExposureStack
from hdrio.synthetic import render_brackets
from tests.conftest import run_cli as run

OFF = 2 ** (1 / 3)  # one bracket's metadata 1/3 stop long


@lru_cache(maxsize=2)
def _stack(scene: str, curve: str) -> tuple[np.ndarray, np.ndarray]:
    """Seven brackets 1 stop apart of a real scene through a real (DoRF/EMoR) response."""
    from benchmarks.truth.curves import load_curve
    from benchmarks.truth.scenes import data_folder, read_scene
    from benchmarks.truth.stacks import exposure_ladder

    truth = read_scene(data_folder("openexr_scenes") / f"{scene}.exr", width=320)
    times = exposure_ladder(truth, 7, 1.0)
    return render_brackets(truth.radiance, times, load_curve(curve).response, seed=3), times


def test_Theil_Sen_anchor_ignores_one_wrong_bracket():
    meta = np.log([1.0, 2.0, 4.0, 8.0, 16.0])
    data = 1.1 * meta + 0.3  # the exponent ambiguity, and one bracket off
    data[3] += 0.5
    anchored = anchor_Theil_Sen(data, meta)
    expected = meta.copy()
    expected[3] += 0.5 / 1.1
    np.testing.assert_allclose(anchored, expected, atol=1e-12)


@pytest.mark.parametrize(("scene", "curve", "wrong"), [("StillLife", "dorf50", 2),
                                                     ("GoldenGate", "dorf100", 6)])
def test_a_wrong_exposure_is_named_and_recovered(scene, curve, wrong, shared_data):
    shared_data("openexr_scenes"), shared_data("crf_database")
    codes, times = _stack(scene, curve)
    meta = times.copy()
    meta[wrong] *= OFF
    files = [f"b{j}.png" for j in range(7)]
    stack = ExposureStack.from_arrays(codes, meta, files=files)
    checked = merge_stack(stack).exposures
    named = checked.warnings()
    assert len(named) == 1 and named[0].startswith(f"b{wrong}.png: "), named
    used = merge_stack(stack, MergeOptions(exposures_from_data=True))
    error = np.abs(np.log2(used.stack.exposures / times))
    # The bound: within 1/50 stop (measured: at most 0.001 stop here).
    assert error.max() < 1 / 50, error
    assert used.exposures.used and used.stack.exposures[wrong] == used.exposures.estimated[wrong]


def test_cli_warns_naming_the_file_and_records_both(shared_data, tmp_path, capsys):
    """EXIF exposures in the files, one 1/3 stop long: one line on stderr naming it, and
    the header holds the metadata's and the data's exposures."""
    shared_data("openexr_scenes"), shared_data("crf_database")
    import OpenImageIO as oiio

    codes, times = _stack("StillLife", "dorf50")
    scale = 1 / 64 / times[0]  # plausible shutter times: 1/64 s and longer
    paths = []
    for j, frame in enumerate(codes):
        t = times[j] * scale * (OFF if j == 4 else 1.0)
        paths.append(write_image(tmp_path / f"shot{j}.png", frame, "uint8",
                                 {"ExposureTime": float(t)}))
    output = tmp_path / "out.exr"
    code, _, err = run(capsys, "merge", *paths, "-q", "-o", output)
    assert code == 0, err
    lines = [line for line in err.splitlines() if "warning" in line]
    assert len(lines) == 1 and "shot4.png: exposure 1/3.175 in the metadata" in lines[0], lines
    code, _, err = run(capsys, "merge", *paths, "-q", "--exposures-from-data", "-o", output)
    assert code == 0, err
    spec = oiio.ImageInput.open(str(output)).spec()
    estimated = np.array(spec.getattribute("hdrio:exposuresEstimated"), float)
    metadata = np.array(spec.getattribute("hdrio:exposuresMetadata"), float)
    used = np.array(spec.getattribute("hdrio:exposures"), float)
    assert spec.getattribute("hdrio:exposuresFromData") == 1
    np.testing.assert_allclose(used, estimated, rtol=1e-6)
    assert abs(np.log2(metadata[4] / estimated[4]) - 1 / 3) < 1 / 50


def test_exposures_from_data_needs_three_brackets(brackets, tmp_path, capsys):
    code, _, err = run(capsys, "merge", *brackets[:2], "--exposures-from-data",
                       "-o", tmp_path / "o.exr")
    assert code == 2 and "--exposures-from-data needs three brackets or more" in err, err
    assert not (tmp_path / "o.exr").exists()
