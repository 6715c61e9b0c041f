#!/usr/bin/env bash
# Makes (once) a Python venv with taichi from PyPI for the MPM peer of `grains bench mpm`
# (shared/peers/mpm/taichi_mpm_bench.py), and prints the venv's python on stdout.
# usage: taichi_venv.sh [VENV_DIR]     (default: $GRAINS_TAICHI_VENV or ~/.cache/grains/taichi-venv)
#
# taichi 1.7 ships wheels for CPython 3.8 to 3.12 only: the first python3.X in that range on
# PATH is used (python3 itself first), and `uv` is tried when there is none.
set -euo pipefail
venv=${1:-${GRAINS_TAICHI_VENV:-$HOME/.cache/grains/taichi-venv}}
TAICHI_SPEC=${TAICHI_SPEC:-taichi==1.7.*}

if [ -x "$venv/bin/python" ] && "$venv/bin/python" -c "import taichi, numpy" >/dev/null 2>&1; then
    echo "$venv/bin/python"
    exit 0
fi

supported() { "$1" -c 'import sys; sys.exit(0 if (3, 8) <= sys.version_info[:2] <= (3, 12) else 1)' 2>/dev/null; }
py=""
for cand in python3 python3.12 python3.11 python3.10 python3.9 python3.8; do
    if command -v "$cand" >/dev/null 2>&1 && supported "$cand"; then
        py=$(command -v "$cand")
        break
    fi
done

echo "taichi_venv: creating $venv and installing $TAICHI_SPEC from PyPI (once, about a minute)" >&2
rm -rf "$venv"
mkdir -p "$(dirname "$venv")"
if [ -n "$py" ]; then
    echo "taichi_venv: using $py ($("$py" --version 2>&1))" >&2
    if ! "$py" -m venv "$venv" >&2; then
        echo "taichi_venv: '$py -m venv' failed (Debian: apt-get install python3-venv)" >&2
        exit 1
    fi
    "$venv/bin/python" -m pip install -q --upgrade pip >&2 || true
    "$venv/bin/python" -m pip install -q "$TAICHI_SPEC" >&2
elif command -v uv >/dev/null 2>&1; then
    echo "taichi_venv: no CPython 3.8-3.12 on PATH; letting uv provide 3.12" >&2
    uv venv --python 3.12 "$venv" >&2
    uv pip install --python "$venv/bin/python" "$TAICHI_SPEC" >&2
else
    echo "taichi_venv: taichi 1.7 needs CPython 3.8-3.12 and none is on PATH (nor uv: pip install uv)" >&2
    exit 1
fi
"$venv/bin/python" -c "import taichi, numpy" >/dev/null
echo "taichi_venv: ready: $("$venv/bin/python" -c 'import taichi as ti; print("taichi", ".".join(map(str, ti.__version__)))' 2>/dev/null | tail -1)" >&2
echo "$venv/bin/python"
