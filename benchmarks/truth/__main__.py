"""``python -m benchmarks.truth [--quick] [--out DIR] [--scene PATH ...]``."""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

from benchmarks.truth import DEFAULT_OUT
from benchmarks.truth.config import GROUPS, full_config, quick_config
from benchmarks.truth.harness import run
from benchmarks.truth.methods import select_methods
from benchmarks.truth.report import write_outputs
from benchmarks.truth.scenes import DataMissingError


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.truth",
        description="Ground-truth accuracy, speed and memory of hdrio against OpenCV and "
                    "colour-hdri, on brackets rendered from real scene-linear photographs "
                    "through real camera responses (see docs/accuracy.md).")
    parser.add_argument("--quick", action="store_true",
                        help="2 scenes ~300 px wide, 2 curves, 7 frames 2 EV, 8-bit, 1 repeat")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="output folder (default: benchmarks/results)")
    parser.add_argument("--scene", action="append", type=Path, default=[], metavar="PATH",
                        help="an EXR or Radiance .hdr to use instead of the built-in scenes "
                             "(repeatable)")
    parser.add_argument("--width", type=int, default=None,
                        help="downsample scenes to about this width (0 = full resolution)")
    parser.add_argument("--repeats", type=int, default=None, help="timed calls per method")
    parser.add_argument("--methods", default=None,
                        help="comma-separated method names (default: all)")
    parser.add_argument("--group", action="append", choices=GROUPS, default=[],
                        help="run only this part of the full design (repeatable; "
                             "not with --quick)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    paths = {}
    for path in args.scene:
        if not path.is_file():
            print(f"error: --scene {path}: no such file", file=sys.stderr)
            return 2
        name, n = path.stem, 1
        while name in paths:  # two files with one stem: keep both, apart
            n += 1
            name = f"{path.stem}-{n}"
        paths[name] = str(path.resolve())
    options = {"scene_paths": paths,
               "methods": tuple(args.methods.split(",")) if args.methods else None}
    if args.width is not None:
        options["width"] = args.width or None
    if args.repeats is not None:
        options["repeats"] = args.repeats
    if args.group:
        if args.quick:
            print("error: --group: the quick run has no groups (use it without --quick)",
                  file=sys.stderr)
            return 2
        options["groups"] = tuple(args.group)
    try:
        select_methods(list(options["methods"] or []))
    except KeyError as error:
        print(f"error: {error.args[0]}", file=sys.stderr)
        return 2
    config = (quick_config if args.quick else full_config)(**options)
    command = "python -m benchmarks.truth " + shlex.join(argv if argv is not None
                                                         else sys.argv[1:])
    start = time.perf_counter()
    try:
        results = run(config, progress=lambda message: print(message, flush=True))
    except DataMissingError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    outputs = write_outputs(results, args.out, command.strip())
    print(f"done in {time.perf_counter() - start:.0f} s: "
          + ", ".join(str(p) for p in outputs.values()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
