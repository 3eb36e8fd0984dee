"""The skips of ``hdrio.skips``, each on a scene built to need it, timed on and off.

Every pair of rows runs the same call in the same process, once with the skip and once
with ``--no-skip`` for it (``MergeOptions.no_skip``), so the time it saves is their
difference. Whole ``hdrio merge`` runs (JPEGs in, half EXR out) where the skip acts on
reading or the merge; the solve or the merge alone where that is all it touches (for
``response``: reading the saved response against solving it).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from benchmarks.speed.endtoend import write_jpegs
from benchmarks.speed.scene import (
    bracket_stack,
    covered_scene,
    grey_scene,
    ladder_beyond_scene,
    sky_scene,
    true_response,
)
from benchmarks.timing import measure_alternately
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_files, merge_stack
from hdrio.merge.weighted_mean import merge_brackets
from hdrio.radiometry.saved_response import read_response
from hdrio.response import response_Debevec1997


def _pair(rows: list[dict], name: str, scene: str, on, off, repeats: int) -> None:
    """Time ``on`` and ``off`` alternately (one of each per repeat, after one warm-up
    each), so a drift in the machine's speed falls on both alike; medians."""
    timings = measure_alternately({"on": on, "off": off}, repeats)
    for state, timing in timings.items():
        rows.append({"row": "skips", "method": f"{name} {state}: {scene}", "skip": name,
                     "state": state, "seconds": timing.seconds})


def _merge_files(paths, output, exposures, **options):
    return lambda: merge_files(paths, output, exposures=exposures,
                               options=MergeOptions(**options))


def run(height: int, width: int, repeats: int) -> list[dict]:
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="hdrio-skips-") as folder:
        folder = Path(folder)
        ladder = ladder_beyond_scene(height, width)
        (folder / "ladder").mkdir()
        paths = write_jpegs(ladder, folder / "ladder")
        exposures = [repr(float(t)) for t in ladder.exposures]
        ladder = None
        _pair(rows, "brackets", "9 JPEGs, the shortest all dark, the longest all bright",
              _merge_files(paths, folder / "a.exr", exposures),
              _merge_files(paths, folder / "a.exr", exposures, no_skip=("brackets",)),
              repeats)

        stack, _ = bracket_stack(height, width, 7)
        saved = folder / "saved.exr"
        merge_files(write_jpegs(stack, folder), saved,
                    exposures=[repr(float(t)) for t in stack.exposures])
        _pair(rows, "response", "the benchmark's 7 brackets: read the saved response from "
              "an EXR header, or solve", lambda: read_response(saved),
              lambda: response_Debevec1997(stack), repeats)
        stack = None

        covered = covered_scene(height, width)
        (folder / "covered").mkdir()
        paths = write_jpegs(covered, folder / "covered")
        exposures = [repr(float(t)) for t in covered.exposures]
        covered = None
        merge_files(paths, saved, exposures=exposures, options=MergeOptions(no_skip=("covered",)))
        _pair(rows, "covered", "5 JPEGs 1 EV apart of a 3.5-stop scene",
              _merge_files(paths, folder / "c.exr", exposures),
              _merge_files(paths, folder / "c.exr", exposures, no_skip=("covered",)), repeats)
        _pair(rows, "covered", "the same with a saved response (one JPEG decoded)",
              _merge_files(paths, folder / "c.exr", exposures, response_from=str(saved)),
              _merge_files(paths, folder / "c.exr", exposures, response_from=str(saved),
                           no_skip=("covered",)), repeats)

    grey = grey_scene(height, width)
    _pair(rows, "channels", "7 brackets of a grey scene stored as RGB (solve only)",
          lambda: response_Debevec1997(grey),
          lambda: response_Debevec1997(grey, solve_identical_once=False), repeats)
    grey = None
    sky = sky_scene(height, width)
    response = true_response()
    _pair(rows, "early-stop", "7 brackets, open sky over 40 % of the rows (merge only)",
          lambda: merge_brackets(sky, response)[0],
          lambda: merge_brackets(sky, response, early_stop=False)[0], repeats)
    sky = None
    still, _ = bracket_stack(height, width, 7)
    _pair(rows, "warp", "7 still brackets, --align auto (merge_stack, response given)",
          lambda: merge_stack(still, MergeOptions(deghost="off"), response=response),
          lambda: merge_stack(still, MergeOptions(deghost="off", no_skip=("warp",)),
                              response=response), repeats)
    return rows


def saved_ratios(rows: list[dict]) -> dict[str, float]:
    """``off / on`` time for each scene: how many times faster the skip made it."""
    seconds = {row["method"]: row["seconds"] for row in rows if row.get("row") == "skips"}
    out = {}
    for method, on in seconds.items():
        if " on: " in method:
            off = seconds.get(method.replace(" on: ", " off: "))
            if off and on:
                out[f"skip {method.replace(' on: ', ': ')}: off / on"] = off / on
    return out
