#!/usr/bin/env bash
# Install Segue with its test tools and run the whole check: lint, format, types, tests.
# This is the README's test command and what CI (.ci/run) runs, on a fresh machine.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
# The Redis backend tests run against a real redis-server, which they start on a free port.
if ! command -v redis-server >/dev/null 2>&1; then
    SUDO=""
    if [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1; then SUDO="sudo"; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends redis-server >/dev/null
fi
"$PY" -m pip install --quiet --disable-pip-version-check -e '.[dev]'
"$PY" -m ruff check .
"$PY" -m ruff format --check .
"$PY" -m mypy
"$PY" -m pytest -q "$@"
