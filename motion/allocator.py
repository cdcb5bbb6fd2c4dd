"""Process-wide allocator tuning for numpy-heavy work (opt-in, called by Segue's entry points).

glibc returns large freed blocks to the kernel (``mmap``/heap trimming), so every multi-megabyte
numpy temporary is page-faulted in afresh, 4 KiB at a time. On the virtual machines Segue runs on
that costs ~1 ms per MB, often more than the arithmetic (BVH parse + FK of a 3 MB clip: ~40%).
Keeping freed memory in the heap for reuse removes that cost, at the price of a process holding
on to up to ``trim_threshold`` bytes of free memory.

Segue's CLI, server and workers call :func:`tune_process` (this and one BLAS thread) once at
start-up, and so do the benchmarks (they measure the configuration the processes run with).
Library users may call it too; importing :mod:`motion` never changes the allocator.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from functools import lru_cache

_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3


@lru_cache(maxsize=1)
def tune_allocator(
    mmap_threshold: int = 256 << 20, trim_threshold: int = 512 << 20, top_pad: int = 64 << 20
) -> bool:
    """Keep freed large blocks in the heap (glibc ``mallopt``); returns whether it applied.

    Parameters
    ----------
    mmap_threshold:
        Blocks at least this large (bytes) still get their own mapping.
    trim_threshold:
        Free memory at the top of the heap kept for reuse before returning it to the kernel.
    top_pad:
        Extra bytes requested whenever the heap grows.

    A no-op returning ``False`` on non-glibc platforms.
    """
    if not sys.platform.startswith("linux"):
        return False
    name = ctypes.util.find_library("c") or "libc.so.6"
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    ok = all(
        mallopt(param, value) == 1
        for param, value in (
            (_M_MMAP_THRESHOLD, mmap_threshold),
            (_M_TRIM_THRESHOLD, trim_threshold),
            (_M_TOP_PAD, top_pad),
        )
    )
    return ok


def limit_blas_threads(threads: int = 1) -> bool:
    """Run BLAS (numpy's matrix products) on ``threads`` threads; returns whether it applied.

    Segue's parallelism is processes (worker pools), and its matrix products are small (FK's
    ancestor matrices, per-segment alignments): with one BLAS thread per core already busy,
    OpenBLAS's spinning threads made them 10-50x slower on the 2-core machines measured (parse + FK
    of a salsa clip: 5.8 M joint-frames/s with one thread, 1.2 M with the default while another
    process ran). Needs ``threadpoolctl`` (installed with scikit-learn); a no-op without it.
    """
    try:
        from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]
    except ImportError:
        return False
    threadpool_limits(limits=threads, user_api="blas")
    return True


def tune_process() -> None:
    """What Segue's entry points apply once at start-up: :func:`tune_allocator` and
    :func:`limit_blas_threads` (one BLAS thread per process)."""
    tune_allocator()
    limit_blas_threads(1)
