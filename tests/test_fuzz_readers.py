"""Fuzz tests of the readers: image headers, exposure sidecars, stored responses.

2,000 examples each (hypothesis); the only exception allowed is hdrio's own
(:class:`~hdrio.errors.HdrioError`), whose message names the file it was given.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hdrio.errors import HdrioError
from hdrio.io.brackets import read_codes
from hdrio.io.exposure import read_exposure_table
from hdrio.io.header import read_header
from hdrio.io.write import write_exr, write_image
from hdrio.radiometry.saved_response import check_response_fits, response_from_header

EXAMPLES = settings(max_examples=2000, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])
FOLDER = Path(tempfile.mkdtemp(prefix="hdrio-fuzz-"))


# Slow (hypothesis: hundreds of generated files): deselected by default, run by
# `pytest -m slow` (CI runs both).
pytestmark = pytest.mark.slow


def _seed_files() -> dict[str, bytes]:
    """Small valid files of each kind the readers meet, to mutate."""
    codes = (np.arange(4 * 6 * 3).reshape(4, 6, 3) * 3).astype(np.uint8)
    seeds = {}
    for suffix in (".png", ".jpg", ".tif"):
        seeds[suffix] = write_image(FOLDER / f"seed{suffix}", codes, "uint8").read_bytes()
    exr = write_exr(FOLDER / "seed.exr", np.ones((4, 6, 3), np.float32),
                    {"hdrio:codeMax": 255, "hdrio:responseY": [0.0, 1.0, 2.0, 3.0, 4.0]})
    seeds[".exr"] = exr.read_bytes()
    return seeds


SEEDS = _seed_files()


@st.composite
def damaged_files(draw) -> tuple[str, bytes]:
    """A seed file with some bytes changed and perhaps cut short, or random bytes."""
    suffix = draw(st.sampled_from(sorted(SEEDS)))
    if draw(st.integers(0, 9)) == 0:
        return suffix, draw(st.binary(max_size=256))
    data = bytearray(SEEDS[suffix])
    for _ in range(draw(st.integers(1, 8))):
        position = draw(st.integers(0, len(data) - 1))
        data[position] = draw(st.integers(0, 255))
    cut = draw(st.one_of(st.none(), st.integers(0, len(data))))
    return suffix, bytes(data[:cut])


@EXAMPLES
@given(damaged_files())
def test_image_headers_and_decoding(case: tuple[str, bytes]) -> None:
    suffix, data = case
    path = FOLDER / f"fuzz{suffix}"
    path.write_bytes(data)
    for reader in (read_header, read_codes):
        try:
            reader(path)
        except HdrioError as error:
            assert str(path) in str(error)


_TOKENS = st.sampled_from(["file", "exposure_time_s", "a.png", "b.jpg", "1/60", "0.5", "0",
                           "-1", "nan", "inf", "1/0", "", "#", ",", " ", "\t", '"', "\x00",
                           "\u00e9", "\ufeff", "1e400", "30"])


@st.composite
def sidecars(draw) -> bytes:
    """Text built of sidecar-like tokens, or arbitrary bytes (a fifth of the time)."""
    if draw(st.integers(0, 4)) == 0:
        return draw(st.binary(max_size=200))
    lines = draw(st.lists(st.lists(_TOKENS, max_size=5), max_size=6))
    separator = draw(st.sampled_from([",", " ", ";", ", "]))
    return "\n".join(separator.join(line) for line in lines).encode(
        draw(st.sampled_from(["utf-8", "utf-16", "latin-1"])), errors="replace")


@EXAMPLES
@given(sidecars())
def test_exposure_sidecars(data: bytes) -> None:
    path = FOLDER / "exposures.csv"
    path.write_bytes(data)
    try:
        table = read_exposure_table(path)
    except HdrioError as error:
        assert str(path) in str(error)
        return
    assert all(np.isfinite(t) and t > 0 for t in table.values())


_VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-2**40, 2**40), st.floats(allow_nan=True),
    st.text(max_size=12),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=300),
    st.lists(st.integers(-1000, 70000), max_size=40),
    st.lists(st.text(max_size=4), max_size=6),
    st.builds(np.asarray, st.lists(st.floats(-50, 50), min_size=0, max_size=300)),
)
_KEYS = st.sampled_from(["hdrio:codeMax", "hdrio:responseMethod", "hdrio:responseR",
                         "hdrio:responseG", "hdrio:responseB", "hdrio:responseY",
                         "hdrio:responseSupport", "hdrio:lambda", "hdrio:weighting"])


@st.composite
def stored_headers(draw) -> dict:
    """Headers with some of a stored response's attributes, each of any value type;
    half start from a well-formed response so the checks further in are reached."""
    header: dict = {}
    if draw(st.booleans()):
        code_max = draw(st.sampled_from([255, 1023, 65535]))
        curve = list(np.linspace(-5.0, 1.0, draw(st.integers(2, 300))))
        header = {"hdrio:codeMax": code_max, "hdrio:responseR": curve,
                  "hdrio:responseG": curve, "hdrio:responseB": curve,
                  "hdrio:responseSupport": f"R 1-{code_max - 1}, G 0-{code_max}, B 3-4"}
    header.update(draw(st.dictionaries(_KEYS, _VALUES, max_size=5)))
    return header


@EXAMPLES
@given(stored_headers(), st.sampled_from([255, 65535]), st.sampled_from([1, 3]))
def test_stored_responses(header: dict, code_max: int, channels: int) -> None:
    try:
        response = response_from_header(header, "saved.exr")
        check_response_fits(response, code_max, channels)
    except HdrioError as error:
        assert "saved.exr" in str(error)
        return
    assert np.all(np.isfinite(response.log_inverse))
    assert response.log_inverse.shape == (code_max + 1, channels)
