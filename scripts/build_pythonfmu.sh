#!/usr/bin/env bash
# Build the PythonFMU (FMI 2.0) and PythonFMU3 (FMI 3.0) exports of fmus/pythonfmu/ from pinned PyPI
# packages, into a folder (default target/thirdparty-fmus/), and print what was built.
#
#   scripts/build_pythonfmu.sh [DEST]
#
# Environment: PYTHON (default python3) makes the build venv; FDIMC_PYTHONFMU_VENV (default
# ${XDG_CACHE_HOME:-$HOME/.cache}/fdimc-pythonfmu-0.7.0-3-0.3.4) is where it lives (kept between runs).
#
# Built, each a first-order lag x' = (u - x)/tau, y = x, tau = 0.5 (fmus/pythonfmu/README.md):
#   pythonfmu_lag.fmu          FMI 2.0 CS, `pythonfmu build --no-external-tool` (needsExecutionTool=false)
#   pythonfmu3_lag.fmu         FMI 3.0 CS, `pythonfmu3 build --no-external-tool`
#   pythonfmu_lag_tool.fmu     FMI 2.0 CS, PythonFMU's default flags (needsExecutionTool=true)
#   pythonfmu3_lag_tool.fmu    FMI 3.0 CS, PythonFMU3's default flags (needsExecutionTool=true)
# The exporters' output is not modified (only the .fmu file is renamed). The binaries inside come
# prebuilt in the wheels, so they are the same bytes on every build; modelDescription.xml's guid /
# instantiationToken (a uuid1) and generationDateAndTime, and the zip entries' dates, change from one
# build to the next, so the .fmu files' SHA-256 do too.
#
# The FMUs bundle no Python: their library has the CPython API as undefined symbols and starts an
# interpreter when it is loaded. A host that is not itself Python must put libpython into the process
# first (PythonFMU's README: LD_PRELOAD=/path/to/libpython3.X.so); the script prints the one that
# belongs to the build venv's interpreter.
set -euo pipefail

PYTHONFMU_VERSION=0.7.0
PYTHONFMU3_VERSION=0.3.4
# SHA-256 of the py3-none-any wheels on PyPI (pip --require-hashes refuses anything else).
PYTHONFMU_SHA256=45fb6c1719f172e7370fcbef73452568224f175f5f6656beba90e89b0f51208e
PYTHONFMU3_SHA256=1723ec5937285de07121e1c4eb8e60efdd7b074063a6906a4133408a489ec1da

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
src="$root/fmus/pythonfmu"
dest="${1:-$root/target/thirdparty-fmus}"
python="${PYTHON:-python3}"
venv="${FDIMC_PYTHONFMU_VENV:-${XDG_CACHE_HOME:-$HOME/.cache}/fdimc-pythonfmu-$PYTHONFMU_VERSION-3-$PYTHONFMU3_VERSION}"

mkdir -p "$dest"
dest="$(cd "$dest" && pwd)"

if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
req="$(mktemp)"
work="$(mktemp -d)"
trap 'rm -rf "$req" "$work"' EXIT
cat > "$req" <<EOF
pythonfmu==$PYTHONFMU_VERSION --hash=sha256:$PYTHONFMU_SHA256
pythonfmu3==$PYTHONFMU3_VERSION --hash=sha256:$PYTHONFMU3_SHA256
EOF
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps --require-hashes -r "$req"

# build KIND SCRIPT MODEL OUT [FLAGS...]: one export, renamed to OUT.
build() {
    local tool="$1" script="$2" model="$3" out="$4"
    shift 4
    rm -rf "$work/out" && mkdir -p "$work/out"
    (cd "$work" && "$venv/bin/$tool" build -f "$src/$script" -d "$work/out" "$@" > "$work/log" 2>&1) || {
        cat "$work/log" >&2
        echo "error: $tool build -f $script $* failed" >&2
        exit 1
    }
    mv "$work/out/$model.fmu" "$dest/$out"
}

build pythonfmu PythonFmuLag.py PythonFmuLag pythonfmu_lag.fmu --no-external-tool
build pythonfmu3 PythonFmu3Lag.py PythonFmu3Lag pythonfmu3_lag.fmu --no-external-tool
build pythonfmu PythonFmuLag.py PythonFmuLag pythonfmu_lag_tool.fmu
build pythonfmu3 PythonFmu3Lag.py PythonFmu3Lag pythonfmu3_lag_tool.fmu

echo "built with pythonfmu $PYTHONFMU_VERSION and pythonfmu3 $PYTHONFMU3_VERSION ($("$venv/bin/python" -V)) into $dest:"
"$venv/bin/python" - "$dest" pythonfmu_lag.fmu pythonfmu3_lag.fmu pythonfmu_lag_tool.fmu pythonfmu3_lag_tool.fmu <<'EOF'
import hashlib, os, re, sys, zipfile
dest = sys.argv[1]
for name in sys.argv[2:]:
    path = os.path.join(dest, name)
    with zipfile.ZipFile(path) as z:
        md = z.read("modelDescription.xml").decode()
        libs = [n for n in z.namelist() if n.startswith("binaries/") and not n.endswith("/")]
    def attr(a):
        m = re.search(r'\b%s="([^"]*)"' % a, md)
        return m.group(1) if m else "-"
    sha = hashlib.sha256(open(path, "rb").read()).hexdigest()
    print(f"  {name:26} FMI {attr('fmiVersion')}, {attr('generationTool')}, co-simulation, "
          f"needsExecutionTool={attr('needsExecutionTool')}, sha256 {sha[:16]}")
    print(f"  {'':26} binaries: {', '.join(libs)}")
EOF
libpython="$("$venv/bin/python" -c 'import os, sysconfig as s; d = s.get_config_var("LIBDIR") or ""; n = s.get_config_var("INSTSONAME") or s.get_config_var("LDLIBRARY") or ""; print(os.path.join(d, n) if s.get_config_var("Py_ENABLE_SHARED") else "")')"
if [ -n "$libpython" ] && [ -e "$libpython" ]; then
    echo "at run time, outside Python: LD_PRELOAD=$libpython"
    echo "$libpython" > "$dest/libpython.txt"
else
    echo "warning: $("$venv/bin/python" -V) has no shared libpython (built without --enable-shared): only a Python host (FMPy) can load these FMUs" >&2
fi
