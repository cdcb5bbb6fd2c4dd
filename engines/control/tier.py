"""Whether this process runs the control engine's *secondary* compiled kernels or their NumPy twins.

The control engine's forward DP pass (:func:`engines.control.kernels.forward`) and the motion
kernels (:mod:`motion.compiled`) are always compiled: without them a request costs more than their
compile. The secondary kernels -- template sampling, the interpretation's operands and residuals,
the cost-to-go bound, the re-timing's state alignments and chain -- save a few milliseconds a
request (the re-timing of a salsa dance 6.3 -> 1.3 ms, ``bench/control.py``) but cost about
5 CPU-s to compile in a fresh environment, a third of what a first request (``segue demo control``
with an empty numba cache) paid. Each has a NumPy twin in :mod:`engines.control.dp` that performs
the same floating-point operations in the same order, so both give the same bits
(``tests/engines/test_control_tier.py`` compares them on random problems and on a whole request).
:mod:`motion.numparse` follows the same switch (:func:`motion.jitcache.compiled_ready`).

A process runs the compiled kernels once they are *ready*: ``segue warm`` (run by ``segue serve``
in the background, by ``segue worker`` before its first job and by the Docker image at build)
compiled them into numba's cache and left its stamp there (:func:`stamp`), or this process
compiled them itself (:func:`use_compiled`). Otherwise it runs the twins and compiles nothing but
the forward pass: a one-off command pays no compile it cannot win back. The choice never changes a
result, only where the milliseconds go.
"""

from __future__ import annotations

import hashlib
import sys
from functools import lru_cache
from pathlib import Path

from motion.jitcache import cache_dir, mark_compiled_ready

_state = {"ready": False}


@lru_cache(maxsize=1)
def stamp() -> Path:
    """The file ``segue warm`` leaves in numba's cache once every kernel a control request runs is
    compiled there: named by a hash of the compiled modules' paths, sizes and modification times
    (what numba keys its entries by), the numba and Python versions and the cache directory."""
    import numba

    from motion import compiled, numparse

    from . import kernels

    here = Path(__file__).resolve().parent
    h = hashlib.sha256(f"{numba.__version__} {sys.version}".encode())
    for path in (
        Path(str(kernels.__file__)),
        Path(str(compiled.__file__)),
        Path(str(numparse.__file__)),
        here / "warm.py",
        here / "tier.py",
    ):
        path = path.resolve()
        st = path.stat()
        h.update(f"{path} {st.st_size} {st.st_mtime_ns}".encode())
    return cache_dir() / f"segue-warm-{h.hexdigest()[:16]}"


def use_compiled() -> None:
    """From now on, this process runs the compiled secondary kernels (``segue warm`` calls this
    before it runs its requests, so that it compiles them)."""
    _state["ready"] = True
    mark_compiled_ready()


def compiled_ready() -> bool:
    """Whether to run the compiled secondary kernels: this process asked for them
    (:func:`use_compiled`) or ``segue warm`` stamped numba's cache (checked each call until
    found: a server's background warm finishes while it serves)."""
    if not _state["ready"] and stamp().exists():
        use_compiled()
    return _state["ready"]
