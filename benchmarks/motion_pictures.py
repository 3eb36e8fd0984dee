"""Before/after crops of the two real hand-held stacks for docs/motion.md.

``python -m benchmarks.motion_pictures [docs/images]``: merges
``../shared/data/hdrtoolbox_stacks/{alignment,ghost}`` with ``--align off --deghost off``
and with the defaults, tone-maps both the same way (Reinhard global, the key of the
default merge), and writes side-by-side crops (left: off, right: auto) as JPEG, plus the
motion mask of the ghost stack.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from benchmarks.truth.scenes import data_folder
from hdrio.io.brackets import read_brackets
from hdrio.io.write import write_image
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_stack
from hdrio.tonemap.preview import render_preview

CROPS = {  # (top, left, height, width) in the stack's pixels
    "alignment": (40, 0, 300, 300),
    "ghost": (300, 440, 220, 320),
}


def merged(name: str, options: MergeOptions):
    folder = data_folder("hdrtoolbox_stacks")
    files = sorted(p for p in (folder / name).iterdir() if p.suffix.lower() == ".jpg")
    stack = read_brackets(files, exposures_from=folder / "exposures.csv")
    return merge_stack(stack, options)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    out = Path(args[0] if args else "docs/images")
    for name, (top, left, height, width) in CROPS.items():
        before = merged(name, MergeOptions(align="off", deghost="off"))
        after = merged(name, MergeOptions(align="auto", deghost="auto"))
        panels = []
        for result in (before, after):
            pixels = render_preview(result.radiance, "reinhard-global", result.options.colourspace)
            panels.append(pixels[top:top + height, left:left + width])
        gap = np.ones((height, 4, 3))
        picture = np.concatenate([panels[0], gap, panels[1]], axis=1)
        codes = np.round(np.clip(picture, 0, 1) * 255).astype(np.uint8)
        write_image(out / f"motion_{name}.jpg", codes, "uint8")
        print(f"{name}: {', '.join(after.motion.alignment.describe()) or 'no motion'}; "
              f"deghosted {100 * after.motion.deghosting.fraction:.1f} %")
        if name == "ghost":
            h, w = after.stack.shape[:2]
            mask = after.motion.deghosting.motion_mask(h, w)
            grey = np.round(mask[..., None].repeat(3, -1) * 255).astype(np.uint8)
            write_image(out / "motion_ghost_mask.png", grey[::2, ::2], "uint8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
