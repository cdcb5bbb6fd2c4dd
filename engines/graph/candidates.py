"""Near-linear candidate transitions: local minima of the cost matrix found from a
nearest-neighbour index, instead of the all-pairs scan (:func:`engines.graph.build.local_minima`).

The all-pairs scan computes every entry of the ``N x N`` matrix ``M[x, y] = ||rows[x] - rows[y]||^2``
and keeps the entries below ``tau`` that are local minima of their 3x3 neighbourhood within their
clip-pair block (Arikan & Forsyth 2002, Sec. 3.1; Kovar et al. 2002): ``O(N^2)`` time, and edges
that grow faster than ``N`` (on Bandai-Namco, 86k frames have ~1,400 frames each below ``tau = 1``).

Here:

1. **Seeds.** An inverted-file index (``faiss.IndexIVFFlat``: a seeded k-means into ``N / 256``
   cells, exact distances within the ``nprobe`` cells probed) holds every :data:`STRIDE`-th frame;
   every :data:`STRIDE`-th frame asks it for its ``k`` nearest held frames outside its own clip's
   ``min_jump_frames`` window. A seed is such a pair ``(a, b)``. The strides spread the ``k``
   neighbours over more valleys of ``M`` (a valley runs along the diagonal and is several frames
   wide, so neighbouring frames of one match would otherwise fill the ``k`` places).
2. **Descent.** From every seed, steepest descent over 3x3 neighbourhoods within the seed's
   clip-pair block (:func:`engines.graph.descent.descend`, compiled) to the local minimum of its
   basin; the minimum is kept when below ``tau``, outside the clip's own window and a minimum by the
   all-pairs scan's rule (same tie rule, same clip borders). Seeds ending in one minimum count once.

So every kept edge is one the all-pairs scan keeps, at most ``N * k / STRIDE`` of them, and the work
is ``O(N k)`` besides the index. What it misses: minima whose basin holds no seed (a frame with
many near-equal matches, as standing still, whose extra matches add little). Recall against the
all-pairs scan: ``bench/graph_build.py --recall``.

Reproducible: the k-means is seeded and trained on an evenly strided sample, the searches are exact
within the probed cells and the descent is deterministic, so the result does not depend on the
number of threads.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..base import EngineError, ShouldStop
from .descent import descend

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
Progress = Callable[[float, str], None]

NEIGHBOURS = 24
"""Seeds per querying frame: its nearest held frames outside its clip's ``min_jump_frames`` window."""
STRIDE = 2
"""Every ``STRIDE``-th frame is held by the index and asks it for seeds."""
CHUNK = 16384
"""Querying frames per step (bounds memory: ``CHUNK * (k + window)`` seeds)."""
CELL_FRAMES = 256
"""Held frames per cell of the inverted file, on average."""
NPROBE = 16
"""Cells probed per query."""
TRAIN_PER_CELL = 64
"""Training rows per cell for the index's k-means (an evenly strided sample)."""
TRAIN_MAX = 262_144
"""Training rows of the k-means at most (keeps training linear in the frames past 4,096 cells)."""
MAX_STEPS = 256
"""Moves of one descent at most (a seed that has not settled by then is dropped)."""
SEED = 1234


@dataclass(frozen=True, slots=True)
class IndexStats:
    """Figures of the indexed search: cells of the index, cells probed, seeds per querying frame,
    distinct seeds, distinct minima reached, those kept (below ``tau``, outside the window), and the
    dimensions searched."""

    cells: int
    probed: int
    neighbours: int
    seeds: int
    reached: int
    minima: int
    dims: int


def never_stop() -> bool:
    """A ``should_stop`` that never asks to stop."""
    return False


def no_progress(fraction: float, message: str) -> None:
    """A ``progress`` that reports nowhere."""


@dataclass(frozen=True, slots=True)
class FrameIndex:
    """The inverted-file index of a build: ``held (H,)`` the row indices it holds (every
    ``stride``-th row), ``ivf`` the trained and filled ``faiss.IndexIVFFlat`` over those rows,
    ``cells`` its cells and ``probed`` the cells a query probes. Built once per build
    (:func:`frame_index`) and asked twice: by every held frame for seeds, and by the frames of the
    clips the first pass left out (:func:`engines.graph.build.bridge_edges`)."""

    held: IntArray
    stride: int
    ivf: Any
    cells: int
    probed: int


def frame_index(rows: Float32Array, stride: int = STRIDE, workers: int = 1) -> FrameIndex:
    """The index over every ``stride``-th of ``rows (N, D)`` float32.

    Cells: ``H / CELL_FRAMES`` (at most 65,536); the k-means is trained on an evenly strided sample of
    ``TRAIN_PER_CELL`` rows a cell, at most :data:`TRAIN_MAX` rows, so training is linear in ``N``
    past ``TRAIN_MAX / TRAIN_PER_CELL`` cells. Time ``O(N)`` besides the quantizer's
    ``cells``-wide comparisons (``O(N^2 / CELL_FRAMES)``, a few seconds at 1M frames)."""
    import faiss  # a heavy import: only for builds

    if stride < 1:
        raise EngineError(f"stride must be >= 1, got {stride}")
    held = np.arange(0, int(rows.shape[0]), stride, dtype=np.int64)
    data = np.ascontiguousarray(rows[held], dtype=np.float32)
    faiss.omp_set_num_threads(max(1, workers))
    n, d = data.shape
    nlist = max(1, min(n // CELL_FRAMES, 65536))
    quantizer = faiss.IndexFlatL2(d)
    ivf = faiss.IndexIVFFlat(quantizer, d, nlist, faiss.METRIC_L2)
    ivf.cp.seed = SEED
    ivf.cp.niter = 10
    ivf.cp.max_points_per_centroid = TRAIN_PER_CELL * 4
    step = max(1, n // min(nlist * TRAIN_PER_CELL, TRAIN_MAX))
    ivf.train(np.ascontiguousarray(data[::step]))
    ivf.add(data)
    probed = min(NPROBE, nlist)
    ivf.nprobe = probed
    return FrameIndex(held, stride, ivf, nlist, probed)


def indexed_minima(
    rows: Float32Array,
    offsets: IntArray,
    tau: float,
    min_jump_frames: int,
    *,
    neighbours: int = NEIGHBOURS,
    stride: int = STRIDE,
    queries: IntArray | None = None,
    index: FrameIndex | None = None,
    workers: int = 1,
    progress: Progress = no_progress,
    should_stop: ShouldStop = never_stop,
) -> tuple[IntArray, IntArray, FloatArray, IndexStats]:
    """Local minima below ``tau`` of ``M[x, y] = ||rows[x] - rows[y]||^2``, ``x < y``, reached by
    descent from the index's seeds (module docstring).

    ``rows (N, D)`` float32; ``offsets (C + 1,)`` each clip's first row. The index (``index``, built
    over ``rows`` by :func:`frame_index`, or built here) holds every ``stride``-th row (the index's
    own stride when given); ``queries`` (sorted row indices) ask it for seeds, by default the held
    rows. Entries of one clip with
    ``|y - x| < min_jump_frames`` are never kept (they still count as neighbours). ``workers``
    threads search the index and descend. Returns ``(x, y, cost, stats)``: row indices sorted by
    ``(x, y)`` and float32-accurate costs. Raises :class:`InterruptedError` when ``should_stop()``
    turns true (polled per chunk of :data:`CHUNK` querying frames), :class:`EngineError` for bad
    settings.
    """
    if neighbours < 1 or stride < 1:
        raise EngineError(f"neighbours and stride must be >= 1, got {neighbours} and {stride}")
    rows = np.ascontiguousarray(rows, dtype=np.float32)
    n, dims = int(rows.shape[0]), int(rows.shape[1])
    counts = np.diff(offsets)
    clip = np.repeat(np.arange(counts.size, dtype=np.int64), counts)
    if index is not None:
        stride = index.stride
    held = np.arange(0, n, stride, dtype=np.int64)
    if held.size < 2:
        z = np.zeros(0, dtype=np.int64)
        return z, z.copy(), np.zeros(0), IndexStats(0, 0, neighbours, 0, 0, 0, dims)
    threads = max(1, workers)
    if index is None:
        index = frame_index(rows, stride, threads)
    elif index.held.size != held.size:
        raise EngineError(f"the index holds {index.held.size} rows, not every {stride}th of {n}")
    ivf, nlist, nprobe = index.ivf, index.cells, index.probed
    window = (2 * max(min_jump_frames - 1, 0)) // stride + 1  # held frames of the query's own window
    k = int(min(held.size, neighbours + window))
    tau32 = np.float32(tau)

    def seeds(a: IntArray, found: npt.NDArray[np.int64]) -> tuple[IntArray, IntArray]:
        """The first ``neighbours`` hits of every querying frame outside its window, ``x < y``."""
        q = np.repeat(a, found.shape[1])
        j = found.reshape(-1)
        ok = j >= 0
        q, b = q[ok], held[j[ok]]
        ok = (clip[q] != clip[b]) | (np.abs(b - q) >= min_jump_frames)
        q, b = q[ok], b[ok]
        first = np.concatenate(([0], np.flatnonzero(np.diff(q)) + 1))
        rank = np.arange(q.size) - np.repeat(first, np.diff(np.concatenate((first, [q.size]))))
        ok = rank < neighbours
        key = np.unique(np.minimum(q[ok], b[ok]) * n + np.maximum(q[ok], b[ok]))
        x, y = np.divmod(key, n)
        return x.astype(np.int64), y.astype(np.int64)

    def run(x: IntArray, y: IntArray) -> tuple[IntArray, Float32Array, npt.NDArray[np.bool_], int]:
        ex, ey = np.empty_like(x), np.empty_like(y)
        ev = np.empty(x.size, dtype=np.float32)
        ok = np.empty(x.size, dtype=np.bool_)
        descend(rows, clip, x, y, MAX_STEPS, ex, ey, ev, ok)
        key, first = np.unique(ex * n + ey, return_index=True)
        return key, ev[first], ok[first], int(x.size)

    keys: list[IntArray] = []
    values: list[Float32Array] = []
    oks: list[npt.NDArray[np.bool_]] = []
    n_seeds = 0
    if queries is None:
        queries = held
    starts = list(range(0, queries.size, CHUNK))
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for i, q0 in enumerate(starts):
            if should_stop():
                raise InterruptedError("build cancelled")
            a = queries[q0 : q0 + CHUNK]
            _, found = ivf.search(rows[a], k)
            x, y = seeds(a, found)
            parts = np.array_split(np.arange(x.size), threads)
            futures: list[Future[tuple[IntArray, Float32Array, npt.NDArray[np.bool_], int]]] = [
                pool.submit(run, x[p], y[p]) for p in parts
            ]
            for fut in futures:  # in order: the result does not depend on scheduling
                key, v, ok, s = fut.result()
                keys.append(key)
                values.append(v)
                oks.append(ok)
                n_seeds += s
            progress(
                (i + 1) / len(starts),
                f"transition candidates: frames {int(a[0])}-{int(a[-1])} of {n} "
                f"(clips {int(clip[a[0]])}-{int(clip[a[-1]])})",
            )
    key_all = np.concatenate(keys)
    v_all = np.concatenate(values)
    ok_all = np.concatenate(oks)
    key, first = np.unique(key_all, return_index=True)
    v, ok = v_all[first], ok_all[first]
    x, y = np.divmod(key, n)
    ok &= v < tau32
    ok &= (clip[x] != clip[y]) | (y - x >= min_jump_frames)
    stats = IndexStats(nlist, nprobe, neighbours, n_seeds, int(key.size), int(ok.sum()), dims)
    return x[ok].astype(np.int64), y[ok].astype(np.int64), v[ok].astype(np.float64), stats
