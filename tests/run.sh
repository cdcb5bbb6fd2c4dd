#!/usr/bin/env bash
# Install Segue with its test tools and run the whole check: lint, format, types, tests.
# This is the README's test command and what CI (.ci/run) runs, on a fresh machine.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
# The Redis backend tests run against a real redis-server, which they start on a free port; the
# browser tests (tests/web) drive Debian's chromium through Python playwright (no browser download:
# never `playwright install`). Without /usr/bin/chromium they skip, except with CI=true.
SUDO=""
if [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1; then SUDO="sudo"; fi
APT_UPDATED=""
apt_install() {
    if [ -z "$APT_UPDATED" ]; then $SUDO apt-get update -qq; APT_UPDATED=1; fi
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "$@" >/dev/null
}
if ! command -v redis-server >/dev/null 2>&1; then apt_install redis-server; fi
if [ ! -x /usr/bin/chromium ]; then apt_install chromium || echo "tests/run.sh: chromium not installed" >&2; fi
"$PY" -m pip install --quiet --disable-pip-version-check -e '.[dev,web]'
"$PY" -m ruff check .
"$PY" -m ruff format --check .
"$PY" -m mypy --strict motion engines schemas service workers
"$PY" -m pytest -q "$@"
