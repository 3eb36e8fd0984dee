"""Every command works on the plain install (``pip install -e .``, the README's first
command): none imports a package that only an extra installs.

Here the extras are installed (the test extra runs this), so the commands run in a fresh
interpreter that refuses to import them and records who asked. ``.ci/run`` runs the same
commands on a real plain install (``.ci/smoke_plain_install.sh``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

from tests import hostile as h

# Top-level packages that only an extra installs (pyproject.toml: test, farm, raw, plot,
# bench), and what installs them.
EXTRAS = ("rawpy", "tifffile", "matplotlib", "distributed", "dask", "cv2", "colour_hdri",
          "hypothesis", "pytest")

# Each command in one fresh interpreter where the extras cannot be imported (as on the
# plain install): an import of one raises, and is recorded with the file that asked.
_SCRIPT = textwrap.dedent("""
    import json, sys, traceback

    EXTRAS = set(json.loads(sys.argv[2]))
    asked = []

    class Absent:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] not in EXTRAS:
                return None
            frames = [f.filename for f in traceback.extract_stack()
                      if "importlib" not in f.filename and f.filename != "<string>"]
            asked.append((name, frames[-1] if frames else "?"))
            raise ModuleNotFoundError(f"No module named {name!r} (an extra)", name=name)

    sys.meta_path.insert(0, Absent())
    from hdrio.cli import main

    result = {}
    for name, argv in json.loads(sys.argv[1]).items():
        del asked[:]
        result[name] = {"code": main(argv), "asked": list(asked)}
    print(json.dumps(result))
""")


def test_no_command_imports_an_extra(tmp_path):
    brackets = [str(p) for p in h.ramp_set(tmp_path / "in")]
    h.ramp_set(tmp_path / "shoot", stem="a"), h.ramp_set(tmp_path / "shoot", stem="b")
    out = tmp_path / "out"
    commands = {
        "merge": ["merge", *brackets, "-o", str(out / "m.exr"), "--preview",
                  str(out / "m.jpg"), "-q"],
        "chain": [*brackets, "--merge", "-o", str(out / "c.exr"), "--tonemap",
                  "reinhard-local", "-o", str(out / "c.jpg")],
        "--group": [str(tmp_path / "shoot"), "--threads", "1", "--group", "--merge", "-o",
                    str(out / "{first_stem}.exr")],
        "check": ["check", str(out / "m.exr")],
        "info": ["info", str(out / "m.exr")],
        "export-response": ["export-response", str(out / "m.exr"), "-o", str(out / "ocio")],
        "demo": ["demo", "-o", str(tmp_path / "demo"), "-q"],
    }
    process = subprocess.run(
        [sys.executable, "-c", _SCRIPT, json.dumps(commands), json.dumps(EXTRAS)],
        capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert process.returncode == 0, process.stderr
    result = json.loads(process.stdout.strip().splitlines()[-1])
    assert {name: run["code"] for name, run in result.items()} == {
        name: 0 for name in commands}, process.stderr
    # colour-science's own import looks for Matplotlib (colour.plotting) and does without
    # it; nothing else may ask for an extra.
    asked = {name: [(module, caller) for module, caller in run["asked"]
                    if not (module == "matplotlib" and f"{os.sep}colour{os.sep}" in caller)]
             for name, run in result.items()}
    assert asked == {name: [] for name in commands}, asked
