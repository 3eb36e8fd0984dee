#!/usr/bin/env bash
# Every command a user types, on the plain install (the README's first command: no extras).
#
#   bash .ci/smoke_plain_install.sh VENV DEMO_FOLDER
#
# VENV was made by `pip install -e .` alone; DEMO_FOLDER holds what `hdrio demo` wrote
# (7 brackets, demo.exr). A command that imports an extra (rawpy, tifffile, matplotlib,
# distributed, OpenCV, colour-hdri, hypothesis, pytest) fails here, since none is
# installed: each command must exit as stated, else this script stops with exit 1 and says
# which. It works in a temporary folder and leaves nothing behind.
set -euo pipefail
venv=$(cd "$1" && pwd)
demo=$(cd "$2" && pwd)
hdrio="$venv/bin/hdrio"

fail() { echo "plain-install smoke test FAILED: $*" >&2; exit 1; }

# The venv must be the plain one, or this proves nothing.
"$venv/bin/python" - <<'EOF' || fail "the venv has an extra installed (not a plain install)"
import importlib.util, sys
extras = ["rawpy", "tifffile", "matplotlib", "distributed", "dask", "cv2", "colour_hdri",
          "hypothesis", "pytest"]
found = [name for name in extras if importlib.util.find_spec(name) is not None]
if found:
    print("extras installed: " + ", ".join(found), file=sys.stderr)
    sys.exit(1)
EOF

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"

# expect CODE COMMAND...: run COMMAND, fail unless it exits with CODE.
expect() {
    local want=$1 got=0
    shift
    echo "+ $*"
    "$@" > out.txt 2> err.txt || got=$?
    if [[ $got != "$want" ]]; then
        cat out.txt err.txt >&2
        fail "'$*' exited $got, expected $want"
    fi
}

expect 0 "$hdrio" --version
expect 0 "$hdrio" merge "$demo"/bracket_*.png -o merged.exr --preview merged.jpg
grep -q "^wrote: " out.txt || fail "hdrio merge printed no 'wrote:' line"
expect 0 "$hdrio" "$demo"/bracket_*.png --merge -o chain.exr --tonemap reinhard-local \
    -o chain.jpg
mkdir shoot
for bracket in "$demo"/bracket_*.png; do
    name=$(basename "$bracket")
    cp "$bracket" "shoot/a${name#bracket}"
    cp "$bracket" "shoot/b${name#bracket}"
done
expect 0 "$hdrio" shoot/ --group --merge -o 'hdr/{first_stem}.exr' --tonemap reinhard-global \
    -o 'hdr/{first_stem}.jpg'
[[ $(ls hdr/*.exr | wc -l) == 2 ]] || fail "--group did not write 2 EXRs: $(ls hdr)"
expect 0 "$hdrio" check merged.exr "$demo/demo.exr"
grep -q "range:" out.txt || fail "hdrio check printed no report"
expect 0 "$hdrio" info merged.exr
grep -q "hdrio:sourceFiles" out.txt || fail "hdrio info printed no hdrio:sourceFiles"
expect 0 "$hdrio" export-response merged.exr -o ocio --name demo
[[ -f ocio/config.ocio ]] || fail "export-response wrote no ocio/config.ocio"
expect 0 "$hdrio" demo -o again -q
# Bad input on the plain install: the file named, exit 2 (not an internal error).
expect 2 "$hdrio" check merged.jpg
grep -q "merged.jpg: a JPEG image, not OpenEXR" err.txt || fail "check of a JPEG: $(cat err.txt)"
head -c 2000 merged.exr > truncated.exr
expect 2 "$hdrio" check truncated.exr
grep -q "truncated.exr" err.txt || fail "check of a truncated EXR: $(cat err.txt)"
# What needs an extra says which, naming the file or option (not an internal error).
for name in a b c; do printf 'II*\0' > "$name.CR2"; done
expect 2 "$hdrio" merge a.CR2 b.CR2 c.CR2 -o raw.exr
grep -q "a.CR2: camera RAW needs rawpy.*pip install 'hdrio\[raw\]'" err.txt \
    || fail "RAW without rawpy: $(cat err.txt)"
expect 2 "$hdrio" "$demo"/bracket_*.png --merge --contact-sheet sheet.png
grep -q "pip install 'hdrio\[plot\]'" err.txt || fail "a picture without matplotlib: $(cat err.txt)"
echo "plain-install smoke test: every command works without the extras"
