"""How a 16-bit response's levels are spaced, against the truth, on many camera curves.

``python -m benchmarks.levels [--width 300] [--spacings even,sqrt,toe,auto]``: every
OpenEXR scene of ``../shared/data/openexr_scenes`` rendered by the truth harness at 16
bits (7 x 2 EV and 5 x 1 EV ladders) through DoRF curves 0, 50, 100, 120, 150 and 200,
EMoR's mean curve and a linear sensor's, merged with hdrio's defaults. ``auto`` is the
job's own choice (:func:`hdrio.response.debevec1997.deep_spacing`: ``sqrt`` for a linear
sensor's codes, ``toe`` for any other); ``even``, ``sqrt`` and ``toe`` force that
spacing on every deep stack. Per curve and spacing: the mean over its stacks of the
well-exposed median relative error, of its p99, and of the response's RMS error
(stops) against the true curve (:mod:`benchmarks.truth.metrics`). Prints a table and
writes ``benchmarks/results/levels.json``. The truth harness's own 16-bit and linear
groups are three of these stacks each (EMoR's mean, linear; 400 px wide).
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path
from unittest import mock

from benchmarks.truth.config import Config, StackSpec
from benchmarks.truth.curves import CURVES
from benchmarks.truth.harness import run
from benchmarks.truth.scenes import SCENES

LADDERS = ((7, 2.0), (5, 1.0))
SPACINGS = ("even", "sqrt", "toe", "auto")


def rows_for(spacing: str, width: int, curves: tuple[str, ...],
             scenes: tuple[str, ...] = SCENES) -> list[dict]:
    """The harness's rows of ``hdrio default`` on every scene x curve x ladder at 16 bits,
    the levels spaced ``spacing`` (``auto``: as a job decides)."""
    stacks = tuple(StackSpec(s, c, n, ev, bits=16, group="linear" if c == "linear"
                             else "16-bit") for s in scenes for c in curves
                   for n, ev in LADDERS)
    config = Config("custom", stacks, width, 1, {}, ("hdrio default",))
    if spacing == "auto":
        return run(config)["rows"]
    with mock.patch("hdrio.job.stages.deep_spacing", lambda stack, *_: spacing):
        return run(config)["rows"]


def summary(rows: list[dict], curve: str) -> dict[str, float]:
    """Means over ``curve``'s stacks: well-exposed median and p99 (%), response RMS."""
    ok = [r for r in rows if r["curve"] == curve and r.get("status") == "ok"]
    return {"stacks": len(ok),
            "median": 100 * statistics.fmean(r["well"]["median"] for r in ok),
            "p99": 100 * statistics.fmean(r["well"]["p99"] for r in ok),
            "rms_stops": statistics.fmean(r["response_rms_stops"] for r in ok)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=300)
    parser.add_argument("--spacings", default=",".join(SPACINGS))
    parser.add_argument("--json", default="benchmarks/results/levels.json")
    args = parser.parse_args(argv)
    spacings = args.spacings.split(",")
    unknown = set(spacings) - set(SPACINGS)
    if unknown:
        parser.error(f"--spacings: {', '.join(sorted(unknown))} not one of {SPACINGS}")
    curves = (*CURVES, "linear")
    table = {s: {c: summary(rows, c) for c in curves}
             for s in spacings for rows in [rows_for(s, args.width, curves)]}
    print("well-exposed median % (mean over stacks), p99 %, response RMS stops")
    print(f"{'curve':8s}" + "".join(f"{s:>26s}" for s in spacings))
    for c in curves:
        print(f"{c:8s}" + "".join(
            f"{table[s][c]['median']:9.3f} {table[s][c]['p99']:7.2f} "
            f"{table[s][c]['rms_stops']:8.4f}" for s in spacings))
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps({"width": args.width, "ladders": LADDERS,
                                           "table": table}, indent=1))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
