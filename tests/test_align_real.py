"""Alignment and deghosting on the real hand-held HDR Toolbox stacks (../shared/data)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hdrio.align.registration import estimate_alignment
from hdrio.io.brackets import read_brackets
from hdrio.job.options import MergeOptions
from hdrio.job.output import exr_attributes
from hdrio.job.run import merge_stack

AUTO = MergeOptions(align="auto", deghost="auto")  # the defaults, spelt out


def _stack(shared_data, name):
    folder = shared_data("hdrtoolbox_stacks")
    files = sorted(p for p in (folder / name).iterdir() if p.suffix.lower() == ".jpg")
    return read_brackets(files, exposures_from=folder / "exposures.csv")


def test_hand_held_stack_is_registered_to_under_half_a_pixel(shared_data, monkeypatch):
    result = merge_stack(_stack(shared_data, "alignment"), AUTO)
    motion = result.motion
    assert motion.warped and max(motion.alignment.motion) > 10  # it was hand-held
    # The residual: the same measurement (the strongest gradients: edges) on the aligned
    # brackets, every estimate kept (not snapped to no motion when it fits no better).
    # The bound is 0.5 px; measured 0.03 and 0.10 px at the corners.
    monkeypatch.setattr("hdrio.align.registration.IMPROVEMENT", float("inf"))
    residual = estimate_alignment(result.stack, result.response)
    assert max(residual.motion) < 0.5, residual.motion


def test_walking_people_are_deghosted(shared_data):
    result = merge_stack(_stack(shared_data, "ghost"), AUTO)
    # People walk through the hall between the shots (docs/images/motion_ghost.jpg); the
    # camera stood nearly still (0.3 px). Measured: 4.6 % of pixels deghosted.
    assert max(result.motion.alignment.motion) < 1.0
    assert 0.02 < result.motion.deghosting.fraction < 0.4
    # Each walker is kept as a well-exposed bracket saw it, never from the darkest one
    # (1/100 s, 2 stops under the reference's 1/25 s; the walkers' clothes at codes
    # 1-30): its noise made it agree with every other view, and both moving regions took
    # it (grainy, blocky figures). Measured: both keep the longest bracket's (1/6 s).
    sources = result.motion.deghosting.sources
    assert sources is not None and sources.max() > 0 and not np.any(sources == 0)
    header = exr_attributes(result)
    assert header["hdrio:deghostedFraction"] == pytest.approx(result.motion.deghosting.fraction)
    assert header["hdrio:align"] == "auto" and len(header["hdrio:alignTransforms"]) == 3


def test_readme_and_docs_examples(shared_data, tmp_path, capsys):
    """README's and docs/motion.md's commands on the HDR Toolbox stacks."""
    from tests.conftest import run_cli

    folder = shared_data("hdrtoolbox_stacks")
    sidecar = folder / "exposures.csv"
    canal = sorted((folder / "alignment").glob("*.jpg"))
    code, stdout, err = run_cli(capsys, "merge", *canal, "--exposures-from", sidecar,
                                "-o", tmp_path / "canal.exr", "--preview",
                                tmp_path / "canal.jpg", "--align", "auto", "--deghost", "auto")
    assert code == 0, err
    assert "align:     euclidean" in stdout and "warped" in stdout
    # After a warp the re-merge with the resampling weights is alignment's time, shown
    # inside the align line's.
    assert "(re-merging with resampling weights " in stdout
    hall = sorted((folder / "ghost").glob("*.JPG"))
    code, stdout, err = run_cli(capsys, "merge", *hall, "--exposures-from", sidecar,
                                "-o", tmp_path / "hall.exr", "--align", "auto",
                                "--deghost", "auto")
    assert code == 0, err
    assert "deghost:" in stdout


def test_still_tripod_stack_is_not_deghosted(shared_data):
    """frobisher_001: a tripod scene whose window is clipped in the longer brackets. The
    camera bends the channels next to a clipped one (highlight roll-off, JPEG's chroma and
    ringing): that is not motion. The issue: on still stacks deghosting flags < 0.1 % of
    the pixels and moves the median by < 0.1 % (it flagged 11.4 % and left magenta fringes
    and a grey cell at the window's edge)."""
    import numpy as np

    folder = shared_data("frobisher_001")
    stack = read_brackets(sorted(folder.glob("*.jpg")))
    auto = merge_stack(stack, AUTO)
    off = merge_stack(stack, MergeOptions(align="off", deghost="off"))
    assert not auto.motion.warped
    assert auto.motion.deghosting.fraction < 0.001
    change = np.abs(auto.radiance / off.radiance - 1.0)
    assert np.median(change) < 0.001 and np.percentile(change, 99.9) < 0.01


def test_memorials_listed_exposures_are_not_read_as_motion(shared_data, tmp_path, capsys):
    """memorial (16 scans, still): its exposure list says 1/1024 .. 32 s in whole stops;
    the data say 1/1161 .. 30.19 s. A bracket off by a few per cent disagrees with its
    neighbours everywhere, which the motion test read as motion where the noise is low:
    5.11 % of the pixels deghosted with the README's command. The test now reads the
    data's exposures (the merge keeps the list's): 1.64 %. Bound 2.5 %: the list read
    again fails it. The issue asks for 0 (docs/motion.md says what is left)."""
    folder = shared_data("memorial_debevec")
    stack = read_brackets(sorted(folder.glob("memorial00*.png")),
                          exposures_from=folder / "exposures.csv")
    result = merge_stack(stack, replace(AUTO, exclude_colour=(0, 0, 255)))
    assert result.exposures is not None and not result.exposures.used
    assert result.motion_test_exposures is not None
    assert result.motion.deghosting.fraction < 0.025, result.motion.deghosting.fraction
    # the merge kept the list's exposures
    assert sorted(result.stack.exposures) == sorted(stack.exposures)
    # and the summary says what the test read
    from tests.conftest import run_cli

    code, stdout, err = run_cli(capsys, "merge", *sorted(folder.glob("memorial00*.png")),
                                "--exposures-from", folder / "exposures.csv",
                                "--exclude-color", "0,0,255", "-o", tmp_path / "m.exr")
    assert code == 0, err
    line = next(line for line in stdout.splitlines() if line.startswith("deghost:"))
    assert line.endswith("; tested with the exposures the data say (the merge's are off "
                         "by up to 0.18 stop)"), line
    from hdrio.io.header import read_header

    header = read_header(tmp_path / "m.exr")
    tested = [float(t) for t in header["hdrio:deghostExposures"]]
    assert len(tested) == 16 and tested == sorted(tested)
    assert tested[0] == pytest.approx(1 / 1161, rel=0.01)  # the list says 1/1024


def test_memorial_is_left_alone_wherever_its_scans_agree(shared_data):
    """What memorial still deghosts (1.64 %, the README command) is the chandelier, top
    right, where the scans do not show one still scene: there the 1/2 s scan's codes
    (memorial0067.png, the motion test's reference) are more than 8 above the 1 s
    scan's (memorial0066.png), which had twice the light, at 12 % of the pixels (a
    response is monotone; elsewhere in the frame 0-0.6 %, measured on four regions).
    Wherever the motion layer is 0 the merge is bit for bit `--deghost off`'s, and the
    layer stays in the top right quarter."""
    folder = shared_data("memorial_debevec")
    stack = read_brackets(sorted(folder.glob("memorial00*.png")),
                          exposures_from=folder / "exposures.csv")
    options = replace(AUTO, exclude_colour=(0, 0, 255))
    result = merge_stack(stack, options)
    still = merge_stack(stack, replace(options, deghost="off"))
    codes = np.asarray(result.stack.codes).astype(np.int16)
    reference = result.motion.deghosting.reference
    height, width = codes.shape[1:3]

    def above(rows: slice, cols: slice) -> float:  # the reference over the next scan
        a, b = codes[reference, rows, cols], codes[reference + 1, rows, cols]
        told = (a.max(axis=-1) < 250) & ~np.all(a == (0, 0, 255), axis=-1) \
            & ~np.all(b == (0, 0, 255), axis=-1)
        return float(np.mean(np.any(a - b > 8, axis=-1)[told]))

    assert above(slice(8, 90), slice(430, 512)) > 0.08  # the chandelier
    for rows, cols in ((slice(8, 90), slice(300, 380)), (slice(330, 420), slice(150, 350)),
                       (slice(650, 760), slice(100, 400))):  # ceiling, mural, floor
        assert above(rows, cols) < 0.01
    layer = result.motion.deghosting.motion_mask(height, width)
    moved = layer > 0
    assert 0 < np.mean(moved) < 0.025
    assert not moved[height // 4:].any() and not moved[:, : width // 2].any()
    radiance, reference_radiance = np.asarray(result.radiance), np.asarray(still.radiance)
    assert np.array_equal(radiance[~moved], reference_radiance[~moved])
