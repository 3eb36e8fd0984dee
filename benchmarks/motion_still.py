"""Alignment and deghosting on still stacks: nothing may be warped or deghosted.

``python -m benchmarks.motion_still [--width 300]``: every OpenEXR scene of
``../shared/data/openexr_scenes`` rendered through DoRF curves 0 and 100 (the truth
harness's 7-frame, 2 EV ladder, 8-bit PNG and JPEG quality 90), merged with
``--align auto --deghost auto`` and with both ``off``. Per stack: whether a bracket was
warped, the brackets refused as too clipped to register, the fraction deghosted, and the
median relative error of both merges against the truth. The issue's bounds: nothing
warped, < 0.1 % deghosted, the median moved by < 0.1 %. Prints a table and writes
``benchmarks/results/motion_still.json``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from benchmarks.truth.config import REFERENCE_LADDER, StackSpec
from benchmarks.truth.curves import load_curve
from benchmarks.truth.methods import exposure_stack
from benchmarks.truth.scenes import data_folder, read_scene
from benchmarks.truth.stacks import render_stack
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_stack
from hdrio.tools.synthetic import radiance_error

CURVES = ("dorf0", "dorf100")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=300)
    parser.add_argument("--json", default="benchmarks/results/motion_still.json")
    args = parser.parse_args(argv)
    frames, ev = REFERENCE_LADDER
    folder = data_folder("openexr_scenes")
    rows = []
    print(f"{'scene':12s} {'curve':8s} {'jpeg':5s} {'warped':6s} {'refused':10s} "
          f"{'deghosted':>9s} {'median off':>10s} {'auto':>8s} {'moved':>8s}")
    for path in sorted(folder.glob("*.exr")):
        scene = read_scene(path, args.width)
        for curve in CURVES:
            for jpeg in (False, True):
                spec = StackSpec(path.stem, curve, frames, ev, jpeg=jpeg)
                rendered = render_stack(spec, scene, load_curve(curve))
                stack = exposure_stack(rendered)
                off = merge_stack(stack, MergeOptions(align="off", deghost="off"))
                auto = merge_stack(stack, MergeOptions(align="auto", deghost="auto"))
                a = radiance_error(off.radiance, rendered.truth)["median"]
                b = radiance_error(auto.radiance, rendered.truth)["median"]
                row = {"scene": path.stem, "curve": curve, "jpeg": jpeg,
                       "warped": bool(auto.motion.warped),
                       "refused": [j for j, _ in auto.motion.alignment.refused],
                       "deghosted": auto.motion.deghosting.fraction,
                       "median_off": a, "median_auto": b, "moved": b / a - 1.0}
                rows.append(row)
                print(f"{row['scene']:12s} {curve:8s} {jpeg!s:5s} {row['warped']!s:6s} "
                      f"{str(row['refused']):10s} {100 * row['deghosted']:8.3f}% "
                      f"{a:10.4f} {b:8.4f} {100 * row['moved']:+7.3f}%", flush=True)
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"width": args.width, "rows": rows}, indent=2))
    bad = [r for r in rows if r["warped"] or r["deghosted"] >= 0.001
           or abs(r["moved"]) >= 0.001]
    print(f"{len(rows)} still stacks, {len(bad)} outside the bounds")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
