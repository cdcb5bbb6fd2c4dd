"""Whether tests/run.sh may skip ``pip install -e '.[dev,web]'`` (it takes 30-70 s even when nothing
changed).

``python -E tests/install_current.py`` exits 0 (and prints nothing) when all of these hold, else 1
with the first reason on stderr:

* the installed ``segue`` distribution is the editable install of this checkout (its
  ``direct_url.json``), and ``service`` imports from this checkout (not from another clone that was
  installed into the same environment since);
* the stamp written by ``--write`` after this checkout's last install matches: a hash of
  pyproject.toml, the Python version and executable, and the checkout's path (a changed pyproject
  reinstalls);
* every requirement of ``segue[dev,web]`` is installed at a version it allows.

``--write`` records the stamp (tests/run.sh runs it after a successful install). Stamps live in
``$XDG_CACHE_HOME/segue/pip-stamps`` (default ~/.cache), one per Python executable and checkout.
Run with ``-E`` so that PYTHONPATH cannot make a checkout that is not installed look installed.
"""

from __future__ import annotations

import hashlib
import importlib.metadata as md
import importlib.util
import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXTRAS = ("dev", "web")


def stamp_path() -> Path:
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    key = hashlib.sha256(f"{sys.executable}\0{ROOT}".encode()).hexdigest()[:16]
    return cache / "segue" / "pip-stamps" / key


def stamp() -> str:
    h = hashlib.sha256((ROOT / "pyproject.toml").read_bytes())
    h.update(f"\0{sys.version}\0{sys.executable}\0{ROOT}".encode())
    return h.hexdigest()


def _installed_here() -> str | None:
    try:
        dist = md.distribution("segue")
    except md.PackageNotFoundError:
        return "segue is not installed"
    direct = json.loads(dist.read_text("direct_url.json") or "{}")
    if not direct.get("dir_info", {}).get("editable"):
        return "segue is not an editable install"
    if direct.get("url") != ROOT.as_uri():
        return f"segue is installed from {direct.get('url')}, not from {ROOT.as_uri()}"
    spec = importlib.util.find_spec("service")
    if spec is None or spec.origin is None or not Path(spec.origin).resolve().is_relative_to(ROOT):
        return f"service imports from {spec and spec.origin}, not from {ROOT}"
    return None


def _requirements_met() -> str | None:
    try:
        from packaging.requirements import Requirement
    except ImportError:
        return "packaging is not installed (cannot check the requirements)"
    for text in md.requires("segue") or []:
        req = Requirement(text)
        env = [{"extra": extra} for extra in ("", *EXTRAS)]
        if req.marker is not None and not any(req.marker.evaluate(e) for e in env):
            continue  # an extra we do not install, or another platform's
        try:
            version = md.version(req.name)
        except md.PackageNotFoundError:
            return f"{req.name} is not installed"
        if not req.specifier.contains(version, prereleases=True):
            return f"{req.name} {version} does not satisfy {req}"
    return None


def main(argv: list[str]) -> int:
    if argv == ["--write"]:
        path = stamp_path()
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(stamp() + "\n")
        return 0
    if argv:
        print("usage: python -E tests/install_current.py [--write]", file=sys.stderr)
        return 2
    path = stamp_path()
    reason = _installed_here()
    if reason is None and (not path.exists() or path.read_text().strip() != stamp()):
        reason = "pyproject.toml, the Python or the checkout changed since the last install"
    reason = reason or _requirements_met()
    if reason:
        print(f"tests/install_current.py: {reason}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
