#!/usr/bin/env bash
# Install Segue with its test tools and run the whole check: lint, format, types, tests.
# This is the README's test command and what CI (.ci/run) runs, on a fresh machine.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
"$PY" -m pip install --quiet --disable-pip-version-check -e '.[dev]'
"$PY" -m ruff check .
"$PY" -m ruff format --check .
"$PY" -m mypy
"$PY" -m pytest -q "$@"
