#!/usr/bin/env bash
# Install Segue with its test tools and run the whole check: lint, format, types, tests.
# This is the README's test command and what CI (.ci/run) runs, on a fresh machine.
#
# What it installs, each only when missing: redis-server, chromium, nodejs and npm with apt (sudo
# when not root); with CI=true also godot3 and xvfb (apt) and Blender as a Python module (bpy from
# PyPI, in its own venv: tests/blender.py); the Khronos glTF-Validator (npm `gltf-validator`,
# pinned, once, into $SEGUE_GLTF_VALIDATOR_DIR, default ~/.cache/segue/gltf-validator: outside the
# work tree; the GLB tests run it with node), and `pip install -e '.[dev,web]'` (pytest, hypothesis, fakeredis, ruff, mypy,
# schemathesis, playwright; playwright drives Debian's /usr/bin/chromium: never
# `playwright install`). The Redis backend tests start their own redis-server on a free port.
#
# The pip step is skipped while tests/install_current.py says the install is current (this
# checkout's editable install, same pyproject.toml and Python, every requirement present): 0.4 s
# instead of 20-70 s.
#
# How much, on the 2-core machine (3 Dec 2026, CPU = user + system of every process): the default
# run about 2.7 CPU-minutes: pytest 158 CPU-s (10.5 min wall at load 10-14), mypy under 1 s with
# its cache (70-140 CPU-s the first time; the cache lives outside the work tree, in $MYPY_CACHE_DIR,
# so every clone on the machine shares it; mypy runs beside pytest), ruff 0.3 s. A fresh machine
# also compiles numba's kernels and librosa's once (about 50 CPU-s). Each step prints its time.
#
# Slow end-to-end tests (marked `slow`: the browser tools in headless Chromium, every example of
# README.md and docs/ run verbatim, the schemathesis fuzz, worker kills, the Redis topology, the 734
# shared-data files) run with CI=true (as CI runs this) or SEGUE_SLOW=1, as do the property-based
# tests' full example counts. No test asserts a time (speed is bench/'s); waits are hang guards
# (60-120 s), so the run passes on a machine busy with other work. Without /usr/bin/chromium the
# browser tests skip, except with CI=true. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
START=$SECONDS
step() { printf 'tests/run.sh: %s (%d s)\n' "$*" "$((SECONDS - START))" >&2; }

SUDO=""
if [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1; then SUDO="sudo"; fi
APT_UPDATED=""
apt_install() {
    step "installing $* with apt"
    if [ -z "$APT_UPDATED" ]; then $SUDO apt-get update -qq; APT_UPDATED=1; fi
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "$@" >/dev/null
}
if ! command -v redis-server >/dev/null 2>&1; then apt_install redis-server; fi
if [ ! -x /usr/bin/chromium ]; then apt_install chromium || echo "tests/run.sh: chromium not installed" >&2; fi
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    apt_install nodejs npm || echo "tests/run.sh: nodejs/npm not installed" >&2
fi
# Godot round trips (tests/motion/test_engine_roundtrip.py, slow): only with CI=true, godot3 and
# xvfb (Godot 3.2's editor needs a display to import) from apt.
if [ "${CI:-}" = "true" ]; then
    if ! command -v godot3 >/dev/null 2>&1 || ! command -v xvfb-run >/dev/null 2>&1; then
        apt_install godot3 xvfb xauth || echo "tests/run.sh: godot3 not installed" >&2
    fi
fi
# A real Blender (tests/blender.py): Blender as a Python module, bpy from PyPI, in a venv of its own
# outside the work tree (bpy pins its Python: 3.11), made only with CI=true and reused while it
# imports; measured at 35 s to make (a 400 MB wheel from the registry). Tests that need it skip
# with a message when SEGUE_BPY_PYTHON is not set.
SEGUE_BPY_VERSION=${SEGUE_BPY_VERSION:-5.0.1}
if [ "${CI:-}" = "true" ]; then
    BPY_VENV="${SEGUE_BPY_VENV:-${XDG_CACHE_HOME:-$HOME/.cache}/segue/bpy-venv}"
    if ! "$BPY_VENV/bin/python" -c "import bpy, sys; sys.exit(bpy.app.version_string != '$SEGUE_BPY_VERSION')" 2>/dev/null; then
        step "pip install bpy==$SEGUE_BPY_VERSION into $BPY_VENV"
        rm -rf "$BPY_VENV"
        "$PY" -m venv "$BPY_VENV"
        "$BPY_VENV/bin/python" -m pip install --quiet --disable-pip-version-check "bpy==$SEGUE_BPY_VERSION"
    fi
    export SEGUE_BPY_PYTHON="$BPY_VENV/bin/python"
fi
GLTF_VALIDATOR_VERSION=2.0.0-dev.3.10  # keep in step with tests/motion/test_gltf_validator.py
export SEGUE_GLTF_VALIDATOR_DIR="${SEGUE_GLTF_VALIDATOR_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/segue/gltf-validator}"
VALIDATOR_PKG="$SEGUE_GLTF_VALIDATOR_DIR/node_modules/gltf-validator/package.json"
if command -v npm >/dev/null 2>&1 && ! grep -q "\"version\": \"$GLTF_VALIDATOR_VERSION\"" "$VALIDATOR_PKG" 2>/dev/null; then
    step "npm install gltf-validator@$GLTF_VALIDATOR_VERSION into $SEGUE_GLTF_VALIDATOR_DIR"
    mkdir -p "$SEGUE_GLTF_VALIDATOR_DIR"
    npm install --prefix "$SEGUE_GLTF_VALIDATOR_DIR" --no-audit --no-fund --silent \
        "gltf-validator@$GLTF_VALIDATOR_VERSION" || echo "tests/run.sh: gltf-validator not installed" >&2
fi
# pip takes 30-70 s even when nothing changed: skip it while this checkout is the editable install,
# pyproject.toml and the Python are those of the last install, and every requirement is present
if "$PY" -E tests/install_current.py; then
    step "pip install skipped (segue[dev,web] is installed from this checkout; tests/install_current.py)"
else
    step "pip install -e '.[dev,web]'"
    "$PY" -m pip install --quiet --disable-pip-version-check -e '.[dev,web]'
    "$PY" -E tests/install_current.py --write
fi

step "ruff"
"$PY" -m ruff check .
"$PY" -m ruff format --check .

export MYPY_CACHE_DIR="${MYPY_CACHE_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/segue/mypy}"
mkdir -p "$MYPY_CACHE_DIR"
MYPY_LOG=$(mktemp)
trap 'rm -f "$MYPY_LOG"' EXIT
step "mypy (in the background; cache $MYPY_CACHE_DIR)"
"$PY" -m mypy --strict motion engines schemas service workers integrations >"$MYPY_LOG" 2>&1 &
MYPY_PID=$!

SELECT=(-m "not slow")
if [ "${CI:-}" = "true" ] || [ "${SEGUE_SLOW:-}" = "1" ]; then SELECT=(); fi
step "pytest ${SELECT[*]:-(all tests)}"
PYTEST_RC=0
"$PY" -m pytest -q "${SELECT[@]}" "$@" || PYTEST_RC=$?

MYPY_RC=0
wait "$MYPY_PID" || MYPY_RC=$?
cat "$MYPY_LOG"
step "done: pytest exit $PYTEST_RC, mypy exit $MYPY_RC"
if [ "$PYTEST_RC" -ne 0 ]; then exit "$PYTEST_RC"; fi
exit "$MYPY_RC"
