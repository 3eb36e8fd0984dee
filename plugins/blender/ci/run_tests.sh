#!/usr/bin/env bash
# Blender add-on tests on the real `bpy` module (PyPI), one environment per Blender version
# the manifest claims (blender_version_min 4.5 up to, not including, 5.1: see the README).
#
# bpy 4.5.x and 5.0.x are cp311 wheels (~370 MB each) that require numpy<2, so each version
# gets two venvs, kept in a cache outside the checkout (CI runs in a fresh clone, and
# rebuilding them costs minutes), named after what they hold so a change remakes them:
#   <cache>/<version>-<key>        bpy + hdrio's dependencies on numpy 1.26, colour-science
#                                  0.4.6, OpenImageIO 3.0.x, pytest; hdrio itself comes
#                                  from the checkout (pytest's pythonpath), never installed;
#   <cache>/<version>-fresh        bpy alone: the built extension zip is installed into a
#                                  throw-away user folder there, proving it brings hdrio and
#                                  its dependencies itself.
# <cache> is $HDRIO_BLENDER_CACHE, else ~/.cache/hdrio-blender. Needs python3.11 and the
# package index (the extension build downloads wheels, pip's own cache keeps them).
#
#   bash plugins/blender/ci/run_tests.sh            # set up (once) and test every version
#   HDRIO_BLENDER_VERSIONS="5.0" bash plugins/blender/ci/run_tests.sh
#   HDRIO_BLENDER_SETUP_ONLY=1 bash plugins/blender/ci/run_tests.sh
# The extension zip is built once and its path given to the tests in HDRIO_BLENDER_ZIP
# (set it to test a zip built elsewhere).
set -euo pipefail
cd "$(dirname "$0")/../../.."
root="$(pwd)"
python="${HDRIO_BLENDER_PYTHON:-python3.11}"
versions="${HDRIO_BLENDER_VERSIONS:-4.5 5.0}"
cache="${HDRIO_BLENDER_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/hdrio-blender}"
mkdir -p "$cache"

# hdrio's runtime dependencies (pyproject.toml) with the Blender pins, one per line.
requirements() {
    "$python" - "$root/pyproject.toml" <<'PY'
import sys, tomllib
with open(sys.argv[1], "rb") as f:
    project = tomllib.load(f)["project"]
pins = {"numpy": "numpy==1.26.*", "colour-science": "colour-science==0.4.6",
        "OpenImageIO": "OpenImageIO==3.0.*"}
for requirement in project["dependencies"]:
    name = requirement.split(">")[0].split("=")[0].split("<")[0].strip()
    print(pins.get(name, requirement))
print("pytest>=8")
PY
}

# make_venv DIR CHECK_IMPORTS PACKAGES...: create DIR unless its imports already work.
make_venv() {
    local venv="$1" imports="$2"
    shift 2
    if [[ -x "$venv/bin/python" ]] && "$venv/bin/python" -c "import $imports" >/dev/null 2>&1; then
        return
    fi
    echo "== creating $venv"
    # A venv half made (an interrupted run) fails the import check above and is remade.
    rm -rf "$venv"
    "$python" -m venv "$venv"
    "$venv/bin/python" -m pip install -q "$@"
}

setup() {
    local version="$1" key
    mapfile -t wanted < <(requirements)
    key="$(printf '%s\n' "$version" "${wanted[@]}" | sha256sum | cut -c1-12)"
    venv="$cache/$version-$key"
    fresh="$cache/$version-fresh"
    make_venv "$venv" "bpy, numpy, colour, OpenImageIO, numba, pytest" \
        "bpy==$version.*" "${wanted[@]}"
    make_venv "$fresh" "bpy" "bpy==$version.*"
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
    for environment in "$venv" "$fresh"; do
        if "$environment/bin/python" -I -c "import hdrio" >/dev/null 2>&1; then
            echo "!! $environment must not have hdrio installed" >&2
            exit 1
        fi
    done
}

# One extension zip for every version (the same linux-x64 build), made once per run.
if [[ -z "${HDRIO_BLENDER_SETUP_ONLY:-}" && -z "${HDRIO_BLENDER_ZIP:-}" ]]; then
    start=$SECONDS
    dist="$(mktemp -d)"
    trap 'rm -rf "$dist"' EXIT
    HDRIO_BLENDER_ZIP="$("$python" -m plugins.blender.build --output-dir "$dist" | tail -1)"
    export HDRIO_BLENDER_ZIP
    echo "== built $(basename "$HDRIO_BLENDER_ZIP") ($(du -m "$HDRIO_BLENDER_ZIP" | cut -f1) MB)" \
         "in $((SECONDS - start)) s"
fi

status=0
for version in $versions; do
    start=$SECONDS
    setup "$version"
    echo "== bpy $version environments ready in $((SECONDS - start)) s"
    if [[ -n "${HDRIO_BLENDER_SETUP_ONLY:-}" ]]; then
        continue
    fi
    start=$SECONDS
    echo "== tests/plugins/blender on bpy $version"
    # -m "": every test here, the ones marked slow included (pyproject's addopts leave
    # those out of the README's test command).
    if ! HDRIO_FRESH_BPY_PYTHON="$fresh/bin/python" \
            "$venv/bin/python" -m pytest tests/plugins/blender -q -p no:cacheprovider -m ""; then
        echo "!! Blender $version: tests FAILED" >&2
        status=1
    fi
    echo "== bpy $version tests took $((SECONDS - start)) s"
done
exit "$status"
