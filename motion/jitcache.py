"""Where numba keeps the machine code of Segue's compiled kernels: a cache directory outside the package.

numba's ``cache=True`` writes next to the source (``__pycache__``) unless ``NUMBA_CACHE_DIR`` is
set. Segue sets it, when the user has not, to ``$XDG_CACHE_HOME/segue/numba`` (``~/.cache/segue/
numba``): a read-only install (a system site-packages, a container image run as another user)
still caches, and one cache serves every process of the user (CLI, server, embedded pool, Redis
workers). numba keys each entry by the source file's path and modification time, so checkouts
and versions never share stale code. Call :func:`configure` before ``numba`` is imported (the
modules with compiled kernels do); when numba was imported first (librosa imports it), the
directory is set in its loaded configuration too.

:func:`compiled_ready` says whether this process runs the compiled versions of kernels that have
an exact NumPy twin (:mod:`motion.numparse`, the control engine's secondary kernels,
:mod:`engines.control.tier`): only once ``segue warm`` compiled them, so that a first command does
not pay a compile it cannot win back.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ENV = "NUMBA_CACHE_DIR"

_ready = {"compiled": False}


def cache_dir() -> Path:
    """The numba cache directory in use: ``NUMBA_CACHE_DIR`` when set, else Segue's default."""
    given = os.environ.get(ENV)
    if given:
        return Path(given)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "segue" / "numba"


def configure() -> Path:
    """Set ``NUMBA_CACHE_DIR`` to :func:`cache_dir` (unless the user set it) and return it."""
    path = cache_dir()
    os.environ.setdefault(ENV, str(path))
    numba = sys.modules.get("numba")
    if numba is not None:  # imported before us: its configuration was read already
        config = numba.config
        if not getattr(config, "CACHE_DIR", ""):
            config.CACHE_DIR = os.environ[ENV]
    return path


def mark_compiled_ready() -> None:
    """Say that this process runs compiled kernels rather than their NumPy twins (called once
    ``segue warm`` compiled them: its stamp is in the cache, or this process is warming)."""
    _ready["compiled"] = True


def compiled_ready() -> bool:
    """Whether :func:`mark_compiled_ready` was called in this process."""
    return _ready["compiled"]
