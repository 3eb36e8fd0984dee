"""Build the installable extension zip: the add-on, its manifest, and the wheels it needs.

Blender installs an extension's wheels into its own Python (3.11, with numpy 1.26
bundled), so the zip carries hdrio's wheel and those of its dependencies for one
platform, resolved with numpy 1.26 (the numpy wheel itself is left out: Blender has it)::

    python -m plugins.blender.build                       # dist/hdrio-0.1.0-linux-x64.zip
    python -m plugins.blender.build --platform windows-x64 --output-dir dist

Needs ``pip`` and access to the package index (it downloads the dependency wheels).
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

SOURCE = Path(__file__).resolve().parent
REPOSITORY = SOURCE.parents[1]
MANIFEST = "blender_manifest.toml"
# Blender's platform names -> pip platform tags of wheels that run there.
PLATFORM_TAGS = {
    "linux-x64": ["manylinux2014_x86_64", "manylinux_2_17_x86_64", "manylinux_2_28_x86_64"],
    "windows-x64": ["win_amd64"],
    "macos-arm64": ["macosx_11_0_arm64", "macosx_12_0_arm64", "macosx_13_0_arm64",
                    "macosx_14_0_arm64"],
}
# What the Blender tests run (plugins/blender/ci/run_tests.sh): numpy 1.26 is Blender's.
CONSTRAINTS = ("numpy==1.26.4", "colour-science==0.4.6", "OpenImageIO==3.0.*")
PROVIDED_BY_BLENDER = ("numpy",)
# Wheels the resolver brings that the add-on never imports: colour-science's image I/O
# (imageio, which needs pillow; hdrio reads and writes images with OpenImageIO). Left out,
# 7.5 of 123 MB; the zip test runs every operator in a Blender without them.
NOT_IMPORTED = ("imageio", "pillow")
_MARKER = re.compile(r"^# build\.py adds .*$", re.MULTILINE)


def extension_files() -> list[Path]:
    """The add-on's modules (the build script and CI helpers stay out)."""
    return sorted(p for p in SOURCE.glob("*.py") if p.name != "build.py")


def _pip(*arguments: str) -> None:
    subprocess.run([sys.executable, "-m", "pip", *arguments, "-q",
                    "--disable-pip-version-check"], check=True)


def collect_wheels(platform: str, folder: Path) -> list[Path]:
    """hdrio's wheel and its dependencies' wheels for ``platform`` in ``folder``."""
    # Built from a clean copy: setuptools would reuse (and could ship stale files from)
    # the checkout's build/ folder, and the checkout stays untouched.
    source = folder / "source"
    shutil.copytree(REPOSITORY / "hdrio", source / "hdrio",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPOSITORY / name, source / name)
    _pip("wheel", "--no-deps", "-w", str(folder), str(source))
    shutil.rmtree(source)
    hdrio_wheel = next(folder.glob("hdrio-*.whl"))
    constraints = folder / "constraints.txt"
    constraints.write_text("\n".join(CONSTRAINTS) + "\n")
    tags = [argument for tag in PLATFORM_TAGS[platform] for argument in ("--platform", tag)]
    _pip("download", "--only-binary=:all:", *tags, "--python-version", "3.11",
         "--implementation", "cp", "--abi", "cp311", "--abi", "abi3", "--abi", "none",
         "-c", str(constraints), "-d", str(folder), str(hdrio_wheel))
    constraints.unlink()
    wheels = []
    for wheel in sorted(folder.glob("*.whl")):
        name = wheel.name.split("-")[0].lower().replace("_", "-")
        if name in PROVIDED_BY_BLENDER or name in NOT_IMPORTED:
            wheel.unlink()
        else:
            wheels.append(wheel)
    return wheels


def manifest_text(platform: str, wheels: list[Path]) -> str:
    """The source manifest with this build's ``platforms`` and ``wheels``."""
    text = (SOURCE / MANIFEST).read_text()
    listed = "".join(f'  "./wheels/{wheel.name}",\n' for wheel in wheels)
    added = f'platforms = ["{platform}"]\nwheels = [\n{listed}]'
    if not _MARKER.search(text):
        raise RuntimeError(f"{SOURCE / MANIFEST}: the build marker comment is missing")
    return _MARKER.sub(lambda _: added, text, count=1)


def manifest_fields(text: str) -> dict[str, str]:
    """Top-level ``key = "string"`` fields of a manifest (enough for ``id`` and ``version``;
    the build runs on Python 3.10 too, which has no ``tomllib``)."""
    return dict(re.findall(r'^(\w+)\s*=\s*"([^"]*)"', text.split("\n[", 1)[0], re.MULTILINE))


def build(platform: str, output_dir: Path) -> Path:
    """Write ``<id>-<version>-<platform>.zip`` into ``output_dir`` and return its path."""
    if platform not in PLATFORM_TAGS:
        raise ValueError(f"unknown platform {platform!r}; one of {', '.join(PLATFORM_TAGS)}")
    manifest = manifest_fields((SOURCE / MANIFEST).read_text())
    output_dir.mkdir(parents=True, exist_ok=True)
    target = output_dir / f"{manifest['id']}-{manifest['version']}-{platform}.zip"
    with tempfile.TemporaryDirectory() as temp:
        wheels = collect_wheels(platform, Path(temp))
        partial = target.with_suffix(".partial.zip")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.writestr(MANIFEST, manifest_text(platform, wheels))
            for path in extension_files():
                archive.write(path, path.name)
            for wheel in wheels:
                archive.write(wheel, f"wheels/{wheel.name}", compress_type=zipfile.ZIP_STORED)
        shutil.move(partial, target)
    return target


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plugins.blender.build",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--platform", default="linux-x64", choices=sorted(PLATFORM_TAGS))
    parser.add_argument("--output-dir", type=Path, default=REPOSITORY / "dist")
    args = parser.parse_args(argv)
    print(build(args.platform, args.output_dir))
    return 0


if __name__ == "__main__":
    sys.exit(main())
