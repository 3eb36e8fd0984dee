#!/usr/bin/env bash
# Blender add-on tests on the real `bpy` module (PyPI), one environment per Blender version.
#
# bpy 4.5.x and 5.0.x are cp311 wheels (~370 MB each) that require numpy<2, so each gets
# its own venv under the repository root (gitignored):
#   .venv-blender-<version>        bpy + hdrio (editable) on numpy 1.26, colour-science
#                                  0.4.6, OpenImageIO 3.0.x, pytest: runs the tests;
#   .venv-blender-<version>-fresh  bpy alone: the built extension zip is installed there,
#                                  proving it brings hdrio and its dependencies itself.
# Needs python3.11 on PATH and the package index (the extension build downloads wheels).
#
#   bash plugins/blender/ci/run_tests.sh            # set up (once) and test both versions
#   HDRIO_BLENDER_VERSIONS="5.0" bash plugins/blender/ci/run_tests.sh
#   HDRIO_BLENDER_SETUP_ONLY=1 bash plugins/blender/ci/run_tests.sh
set -euo pipefail
cd "$(dirname "$0")/../../.."
root="$(pwd)"
python="${HDRIO_BLENDER_PYTHON:-python3.11}"
versions="${HDRIO_BLENDER_VERSIONS:-5.0 4.5}"

# make_venv DIR CHECK_IMPORTS PACKAGES...: (re)create DIR unless its imports already work.
make_venv() {
    local venv="$1" imports="$2"
    shift 2
    if [[ -x "$venv/bin/python" ]] && "$venv/bin/python" -c "import $imports" >/dev/null 2>&1; then
        return
    fi
    echo "== creating $venv"
    rm -rf "$venv"
    "$python" -m venv "$venv"
    "$venv/bin/python" -m pip install -q --upgrade pip
    "$venv/bin/python" -m pip install -q "$@"
}

setup() {
    local version="$1" venv="$root/.venv-blender-$1"
    make_venv "$venv" "bpy, hdrio, pytest" "bpy==$version.*" "numpy==1.26.*" \
        "colour-science==0.4.6" "OpenImageIO==3.0.*" "pytest>=8" -e "$root"
    make_venv "$venv-fresh" "bpy" "bpy==$version.*"
    # Fail loudly when an environment is not the one the tests are meant for.
    "$venv/bin/python" - "$version" <<'PY'
import sys
import bpy, numpy, colour, OpenImageIO
want = sys.argv[1]
got = ".".join(str(v) for v in bpy.app.version[:2])
print(f"   bpy {bpy.app.version_string}, numpy {numpy.__version__}, "
      f"colour {colour.__version__}, OpenImageIO {OpenImageIO.VERSION_STRING}")
if got != want or not numpy.__version__.startswith("1.26"):
    sys.exit(f"wrong environment: bpy {got} (want {want}), numpy {numpy.__version__}")
PY
    if "$venv-fresh/bin/python" -c "import hdrio" >/dev/null 2>&1; then
        echo "!! $venv-fresh must not have hdrio installed" >&2
        exit 1
    fi
}

status=0
for version in $versions; do
    setup "$version"
    if [[ -n "${HDRIO_BLENDER_SETUP_ONLY:-}" ]]; then
        continue
    fi
    echo "== tests/plugins/blender on bpy $version"
    if ! HDRIO_FRESH_BPY_PYTHON="$root/.venv-blender-$version-fresh/bin/python" \
            "$root/.venv-blender-$version/bin/python" -m pytest tests/plugins/blender -q \
            -p no:cacheprovider; then
        echo "!! Blender $version: tests FAILED" >&2
        status=1
    fi
done
exit "$status"
