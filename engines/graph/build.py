"""Build of the motion graph (Arikan & Forsyth 2002, Sec. 3.1, 4.1, Appendix A).

``build_graph`` turns a motion library into the arrays of :mod:`engines.graph.model`:

1. Transition features (:mod:`engines.graph.features`): ``C(a, b) = ||x_a - x_b||^2`` for frames
   ``a``, ``b`` of the concatenated clips; feature groups weighed by their largest frame step, the
   whole in units of the database's average frame step (``tau = 1``: a cut as noticeable as one
   average frame of motion).
2. Candidate edges. An edge ``(s, i) -> (t, j)`` (play clip ``s`` up to frame ``i``, continue at
   clip ``t``'s frame ``j``) costs ``C(s_{i+1}, t_j)``: the distance between the frame that would
   have been played next and the frame jumped to, so playing on costs 0. For every ordered clip
   pair, including a clip with itself, the matrix ``P_st[a, b] = C(s_a, t_b)`` is scanned and an
   edge kept where ``P_st[a, b] < tau``, ``a >= 1`` and the entry is a local minimum of its 3x3
   neighbourhood in ``P_st`` (ties go to the first in raster order): the paper's elliptical groups
   of edges shrink to their best cut (as Kovar et al. 2002 do). Cuts within a clip closer than
   ``min_jump_frames`` to playing on (``|j - (i + 1)| < min_jump_frames``) are dropped.
   The scan covers the whole ``N x N`` matrix of the concatenated frames in square tiles
   (``tile`` frames a side, plus a one-frame halo for the neighbourhood test), computed with one
   BLAS product per tile (``[a, |a|^2, 1] . [-2b, 1, |b|^2]^T``); ``C`` is symmetric, so only tiles on
   or above the diagonal are computed and each minimum gives the edges of both directions. Memory:
   the features, one tile and the edges; never an ``N x N`` array. With more than
   :data:`PCA_MIN_DIMS` feature dimensions the scan runs on a PCA reduction (99.9% of the
   variance; its distances are lower bounds) and kept edges get their exact cost.
3. Pruning: the clip graph (``s -> t`` when some edge goes from ``s`` to ``t``; playing a clip to
   its end is a dead end) is split into strongly connected components, the largest (by frames) is
   kept and edges touching other clips are dropped; the report names the dropped clips and why.
4. The edge hierarchy (:mod:`engines.graph.hierarchy`) and the root tracks
   (:mod:`engines.graph.tracks`).
"""

from __future__ import annotations

import json
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from schemas.databases import GraphDatabaseSpec

from ..base import Arrays, BuildWork, Emitter, EngineError, ShouldStop
from ..library import MotionLibrary
from .candidates import (
    FrameIndex,
    IndexStats,
    Progress,
    frame_index,
    indexed_minima,
    never_stop,
    no_progress,
)
from .features import TransitionFeatures, exact_costs, reduce_features, transition_features
from .hierarchy import LeafEdges, build_hierarchy
from .model import RootTracks
from .tracks import foot_contacts, root_tracks

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]

TILE = 2048
"""Side of the square tiles of the cost matrix (frames): 16 MB of float32 per tile."""
PCA_MIN_DIMS = 48
"""Scan on a PCA reduction of the features when they have more dimensions than this."""
PCA_VARIANCE = 0.999
LOCOMOTION_SPEED = 0.5
"""Body speed over the floor (m/s) above which a frame counts as locomotion when the build chooses
the component to keep (:func:`largest_component`)."""
ALL_PAIRS_MAX_FRAMES = 20000
"""Largest library (frames) whose candidate transitions come from the all-pairs scan under
``candidates="auto"``; larger ones use the nearest-neighbour index (``engines.graph.candidates``)."""

# the 8 neighbours, most selective first: the cost's valleys run along the diagonal (frames that
# match keep matching as both clips play on), so neighbours along it reject the most candidates.
# True = strict comparison (neighbours earlier in raster order win ties).
_NEIGHBOURS: tuple[tuple[int, int, bool], ...] = (
    (1, 1, False),
    (-1, -1, True),
    (0, -1, True),
    (0, 1, False),
    (-1, 0, True),
    (1, 0, False),
    (-1, 1, True),
    (1, -1, False),
)


@dataclass(frozen=True, slots=True)
class ScanStats:
    """Figures of the candidate scan: tiles computed, entries below ``tau``, local minima kept."""

    tiles: int
    below_tau: int
    minima: int
    dims: int


class _TileScanner:
    """The cost matrix ``M[x, y] = ||rows[x] - rows[y]||^2`` one tile at a time (see
    :func:`local_minima`)."""

    def __init__(self, rows: npt.NDArray[np.float32], offsets: IntArray, tau: float, min_jump: int) -> None:
        n = int(rows.shape[0])
        counts = np.diff(offsets)
        self.n, self.tau, self.min_jump = n, np.float32(tau), min_jump
        self.clip = np.repeat(np.arange(counts.size, dtype=np.int64), counts)
        # bit 0: first frame of its clip, bit 1: last frame (a neighbour on that side is another clip)
        self.border = np.zeros(n, dtype=np.int8)
        nonempty = counts > 0
        self.border[offsets[:-1][nonempty]] |= 1
        self.border[offsets[1:][nonempty] - 1] |= 2
        sq = np.einsum("ij,ij->i", rows, rows, dtype=np.float64).astype(np.float32)[:, None]
        ones = np.ones((n, 1), dtype=np.float32)
        # [a, |a|^2, 1] . [-2b, 1, |b|^2] = |a - b|^2: one BLAS product per tile
        self.lhs = np.hstack((rows.astype(np.float32, copy=False), sq, ones))
        self.rhs = np.hstack((np.float32(-2.0) * rows, ones, sq))

    def tile(self, r0: int, r1: int, c0: int, c1: int) -> tuple[IntArray, IntArray, FloatArray, int]:
        """Minima ``(x, y, cost)`` with ``x`` in ``[r0, r1)``, ``y`` in ``[c0, c1)``, ``x < y``, and
        the number of entries of the tile below ``tau``."""
        n, clip = self.n, self.clip
        h0, g0 = max(r0 - 1, 0), max(c0 - 1, 0)
        dist = self.lhs[h0 : min(r1 + 1, n)] @ self.rhs[g0 : min(c1 + 1, n)].T  # with a 1-frame halo
        width = dist.shape[1]
        # flatnonzero + divmod: several times faster than a 2-D nonzero
        hit = np.flatnonzero(dist[r0 - h0 : r1 - h0, c0 - g0 : c1 - g0] < self.tau)
        x, y = np.divmod(hit, c1 - c0)
        x += r0
        y += c0
        below = int(x.size)
        if c0 < r1:  # the tile reaches the diagonal
            keep = x < y
            x, y = x[keep], y[keep]
        if clip[c0] <= clip[r1 - 1]:  # some entries compare a clip with itself
            keep = (clip[x] != clip[y]) | (y - x >= self.min_jump)
            x, y = x[keep], y[keep]
        values = dist.reshape(-1)
        flat = (x - h0) * width + (y - g0)
        edge = (self.border[x] | self.border[y] << 2) != 0
        inner = flat[~edge]
        fi, vi = _minima(values, inner, width, None)
        at_edge = flat[edge]
        fb, vb = _minima(values, at_edge, width, (self.border[x[edge]], self.border[y[edge]]))
        flat = np.concatenate((fi, fb))
        x, y = np.divmod(flat, width)
        return x + h0, y + g0, np.concatenate((vi, vb)).astype(np.float64), below


def _minima(
    values: npt.NDArray[np.float32],
    flat: IntArray,
    width: int,
    codes: tuple[npt.NDArray[np.int8], npt.NDArray[np.int8]] | None,
) -> tuple[IntArray, npt.NDArray[np.float32]]:
    """The candidates (``flat`` indices into a tile of ``width`` columns, with a halo) that are local
    minima of their 3x3 neighbourhood, and their values. ``codes`` (the border bits of the
    candidates' rows and columns) masks neighbours in another clip; ``None`` when no candidate
    lies on a clip border. The candidates shrink after every neighbour."""
    v = values[flat]
    cx, cy = codes if codes is not None else (None, None)
    for dx, dy, strict in _NEIGHBOURS:
        idx = flat + (dx * width + dy)
        if cx is not None and cy is not None:
            valid = np.ones(flat.size, dtype=bool)
            if dx:
                valid &= (cx & (1 if dx < 0 else 2)) == 0
            if dy:
                valid &= (cy & (1 if dy < 0 else 2)) == 0
            nb = values[np.where(valid, idx, flat)]
            ok = ~valid | ((v < nb) if strict else (v <= nb))
            cx, cy = cx[ok], cy[ok]
        else:
            nb = values[idx]
            ok = (v < nb) if strict else (v <= nb)
        flat, v = flat[ok], v[ok]
    return flat, v


def local_minima(
    rows: npt.NDArray[np.float32],
    offsets: IntArray,
    tau: float,
    min_jump_frames: int,
    *,
    tile: int = TILE,
    workers: int | None = None,
    progress: Progress = no_progress,
    should_stop: ShouldStop = never_stop,
) -> tuple[IntArray, IntArray, FloatArray, ScanStats]:
    """Local minima below ``tau`` of the cost matrix ``M[x, y] = ||rows[x] - rows[y]||^2``, ``x < y``.

    Neighbourhoods are 3x3 within the clip-pair block of ``x`` and ``y`` (``offsets`` as in
    :class:`~engines.graph.features.TransitionFeatures`); ties go to the entry first in raster
    order. Entries of one clip with ``|y - x| < min_jump_frames`` are never kept (they still count
    as neighbours). Tiles of ``tile`` x ``tile`` entries on and above the diagonal, computed by
    ``workers`` threads (default: the CPUs available; numpy and BLAS release the GIL), so memory
    holds ``workers`` tiles at most besides the results.

    Returns ``(x, y, cost, stats)``: global row indices and the (float32-accurate) costs.
    Raises :class:`InterruptedError` when ``should_stop()`` turns true.
    """
    scanner = _TileScanner(rows, offsets, tau, min_jump_frames)
    n = scanner.n
    starts = list(range(0, n, tile))
    total_tiles = len(starts) * (len(starts) + 1) // 2
    done = below = 0
    xs: list[IntArray] = []
    ys: list[IntArray] = []
    vs: list[FloatArray] = []
    stop = threading.Event()

    def run(r0: int, r1: int, c0: int, c1: int) -> tuple[IntArray, IntArray, FloatArray, int]:
        if stop.is_set():
            raise InterruptedError("build cancelled")
        return scanner.tile(r0, r1, c0, c1)

    with ThreadPoolExecutor(max_workers=max(1, workers or _cpu_count())) as pool:
        for bi, r0 in enumerate(starts):
            r1 = min(r0 + tile, n)
            futures = [pool.submit(run, r0, r1, c0, min(c0 + tile, n)) for c0 in starts[bi:]]
            for fut in as_completed(futures):
                if should_stop():
                    stop.set()
                    for f in futures:
                        f.cancel()
                    raise InterruptedError("build cancelled")
                fut.result()
            for fut in futures:  # in tile order: the result does not depend on scheduling
                x, y, v, b = fut.result()
                xs.append(x)
                ys.append(y)
                vs.append(v)
                below += b
            done += len(futures)
            clips = scanner.clip
            progress(
                done / total_tiles,
                f"transition costs: frames {r0}-{r1 - 1} of {n} (clips {clips[r0]}-{clips[r1 - 1]})",
            )
    x = np.concatenate(xs) if xs else np.zeros(0, dtype=np.int64)
    y = np.concatenate(ys) if ys else np.zeros(0, dtype=np.int64)
    v = np.concatenate(vs) if vs else np.zeros(0)
    return x, y, v, ScanStats(done, below, int(x.size), int(rows.shape[1]))


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# Build cost per frame, measured by bench/graph_scale.py (Bandai-Namco and copies, 100k-1M frames;
# whole worker build: library arrays, graph, quality reference, npz), with a margin.
_INDEXED_CPU_S = (10.0, 2.5e-4)  # seconds: a + b * N
_INDEXED_MB = (400.0, 6.0e-3)  # MiB: a + b * N (measured 5.1e-3: 2.45 GB at 400k, 5.5 GB at 1M)
_ALL_PAIRS_CPU_S = (5.0, 4.0e-9)  # seconds: a + b * N^2
_ALL_PAIRS_MB = (400.0, 1.4e-7)  # MiB: a + b * N^2 (the edges grow about as N^2)


def build_work(frames: int, method: str = "auto") -> BuildWork:
    """Estimated CPU seconds and peak memory (MiB) of a graph build of ``frames`` frames: linear in
    ``frames`` with the index, quadratic with the all-pairs scan (coefficients measured by
    ``bench/graph_scale.py``, with a margin)."""
    n = float(frames)
    if use_index(method, frames):
        return BuildWork(_INDEXED_CPU_S[0] + _INDEXED_CPU_S[1] * n, _INDEXED_MB[0] + _INDEXED_MB[1] * n)
    return BuildWork(
        _ALL_PAIRS_CPU_S[0] + _ALL_PAIRS_CPU_S[1] * n * n, _ALL_PAIRS_MB[0] + _ALL_PAIRS_MB[1] * n * n
    )


def use_index(method: str, frames: int) -> bool:
    """Whether the build finds its candidate transitions with the nearest-neighbour index
    (:mod:`engines.graph.candidates`) rather than the all-pairs scan: ``"indexed"``, ``"all_pairs"``,
    or ``"auto"`` (the index above :data:`ALL_PAIRS_MAX_FRAMES` frames)."""
    if method not in ("auto", "indexed", "all_pairs"):
        raise EngineError(f"candidates must be 'auto', 'indexed' or 'all_pairs', got {method!r}")
    return method == "indexed" or (method == "auto" and frames > ALL_PAIRS_MAX_FRAMES)


def screen_rows(features: TransitionFeatures, pca_min_dims: int = PCA_MIN_DIMS) -> npt.NDArray[np.float32]:
    """The rows the candidate search compares: the features, or their PCA reduction (99.9% of the
    variance; distances are lower bounds) when they have more than ``pca_min_dims`` dimensions."""
    if features.rows.shape[1] > pca_min_dims:
        return reduce_features(features.rows, PCA_VARIANCE)[0]
    return features.rows


def candidate_edges(
    features: TransitionFeatures,
    tau: float,
    min_jump_frames: int,
    *,
    method: str = "all_pairs",
    tile: int = TILE,
    pca_min_dims: int = PCA_MIN_DIMS,
    screen: npt.NDArray[np.float32] | None = None,
    index: FrameIndex | None = None,
    workers: int | None = None,
    progress: Progress = no_progress,
    should_stop: ShouldStop = never_stop,
) -> tuple[LeafEdges, ScanStats | IndexStats]:
    """The edges of G: local minima of the transition cost below ``tau`` (module docstring, step 2),
    both directions of every minimum, sorted by (from clip, to clip, from frame, to frame), found by
    the all-pairs scan or the index (:func:`use_index` of ``method``; ``index`` when given, built
    over ``screen``) on ``screen`` (default :func:`screen_rows`). Costs are recomputed from
    differences of the full feature rows (:func:`~.features.exact_costs`)."""
    if screen is None:
        screen = screen_rows(features, pca_min_dims)
    stats: ScanStats | IndexStats
    if use_index(method, int(features.rows.shape[0])):
        x, y, v, stats = indexed_minima(
            screen,
            features.offsets,
            tau,
            min_jump_frames,
            index=index,
            workers=max(1, workers or _cpu_count()),
            progress=progress,
            should_stop=should_stop,
        )
    else:
        x, y, v, stats = local_minima(
            screen,
            features.offsets,
            tau,
            min_jump_frames,
            tile=tile,
            workers=workers,
            progress=progress,
            should_stop=should_stop,
        )
    return edges_of_minima(features, x, y, tau), stats


BRIDGE_NEIGHBOURS = 64
"""Seeds per frame of the second, denser search from the clips the first left out."""


def bridge_edges(
    features: TransitionFeatures,
    screen: npt.NDArray[np.float32],
    clips: IntArray,
    tau: float,
    min_jump_frames: int,
    *,
    index: FrameIndex | None = None,
    workers: int | None = None,
    should_stop: ShouldStop = never_stop,
) -> LeafEdges:
    """Edges below ``tau`` touching ``clips`` (the clips outside the kept component) that the first
    indexed search may have missed: every frame of those clips (not only the held ones) asks the
    build's index (``index``, over ``screen``; built here when not given) for
    :data:`BRIDGE_NEIGHBOURS` seeds. The edges are the all-pairs scan's (local minima below
    ``tau``), so they connect a clip back where the data allows it. Work: the asking frames' only
    (the index is the first search's, not a second one over every frame)."""
    inside = np.zeros(features.offsets.size - 1, dtype=bool)
    inside[clips] = True
    rows = np.flatnonzero(inside[features.clip_of_row]).astype(np.int64)
    if rows.size == 0:
        return LeafEdges.empty()
    x, y, _, _ = indexed_minima(
        screen,
        features.offsets,
        tau,
        min_jump_frames,
        neighbours=BRIDGE_NEIGHBOURS,
        queries=rows,
        index=index,
        workers=max(1, workers or _cpu_count()),
        should_stop=should_stop,
    )
    return edges_of_minima(features, x, y, tau)


def edges_of_minima(features: TransitionFeatures, x: IntArray, y: IntArray, tau: float) -> LeafEdges:
    """Both edges of every minimum ``(x, y)`` (rows, ``x < y``) whose exact cost is below ``tau``,
    sorted by (from clip, to clip, from frame, to frame)."""
    rows = features.rows
    v = exact_costs(rows, x, y)  # from differences of the full rows: no cancellation, no PCA error
    ok = v < tau
    x, y, v = x[ok], y[ok], v[ok]
    clip = features.clip_of_row
    frame = np.arange(rows.shape[0], dtype=np.int64) - features.offsets[clip]
    fwd = frame[x] >= 1  # edge (clip x, frame x - 1) -> (clip y, frame y)
    bwd = frame[y] >= 1  # edge (clip y, frame y - 1) -> (clip x, frame x)
    leaves = LeafEdges(
        np.concatenate((clip[x[fwd]], clip[y[bwd]])),
        np.concatenate((frame[x[fwd]] - 1, frame[y[bwd]] - 1)),
        np.concatenate((clip[y[fwd]], clip[x[bwd]])),
        np.concatenate((frame[y[fwd]], frame[x[bwd]])),
        np.concatenate((v[fwd], v[bwd])),
    )
    order = np.lexsort((leaves.to_frame, leaves.from_frame, leaves.to_clip, leaves.from_clip))
    return leaves.take(order)


def merge_edges(a: LeafEdges, b: LeafEdges) -> LeafEdges:
    """The union of two sorted edge sets (an edge in both once), sorted as :func:`edges_of_minima`."""
    both = LeafEdges(*(np.concatenate((getattr(a, k), getattr(b, k))) for k in _LEAF_FIELDS))
    order = np.lexsort((both.to_frame, both.from_frame, both.to_clip, both.from_clip))
    both = both.take(order)
    same = np.ones(both.size, dtype=bool)
    same[1:] = (
        (np.diff(both.from_clip) == 0)
        & (np.diff(both.to_clip) == 0)
        & (np.diff(both.from_frame) == 0)
        & (np.diff(both.to_frame) == 0)
    )
    same[0] = False
    return both.take(~same)


_LEAF_FIELDS = ("from_clip", "from_frame", "to_clip", "to_frame", "cost")


def largest_component(
    leaves: LeafEdges, frames: IntArray, names: tuple[str, ...], moving: IntArray | None = None
) -> tuple[npt.NDArray[np.bool_], list[dict[str, Any]]]:
    """Strongly connected components of the clip graph; keeps, among those with an edge inside (a
    lone clip without a transition to itself is no cycle), the one with the most locomotion
    (``moving (C,)``: each clip's frames whose body travels faster than
    :data:`LOCOMOTION_SPEED`; a component without locomotion cannot reach a goal), then the most
    frames, then the most clips. Without ``moving``, the largest by frames.

    Returns a mask of the edges between kept clips and, for every other clip, ``{"clip", "frames",
    "reason"}``.
    """
    c = int(frames.size)
    adj = csr_matrix(
        (np.ones(leaves.size), (leaves.from_clip, leaves.to_clip)), shape=(c, c), dtype=np.float64
    )
    n_comp, label = connected_components(adj, directed=True, connection="strong")
    label = np.asarray(label, dtype=np.int64)
    size_frames = np.bincount(label, frames.astype(np.float64), n_comp)
    size_clips = np.bincount(label, minlength=n_comp)
    internal = label[leaves.from_clip] == label[leaves.to_clip]
    cyclic = np.bincount(label[leaves.from_clip[internal]], minlength=n_comp) > 0
    # a component without an edge inside (a lone clip, no self-transition) cannot be played on
    size_moving = np.bincount(label, (frames * 0 if moving is None else moving).astype(np.float64), n_comp)
    best = int(np.lexsort((size_clips, size_frames, size_moving, cyclic))[-1])
    inside = label == best
    keep = inside[leaves.from_clip] & inside[leaves.to_clip]
    other = leaves.from_clip != leaves.to_clip
    into = np.zeros(c, dtype=bool)  # an edge from the kept component into the clip
    out_of = np.zeros(c, dtype=bool)  # an edge from the clip into the kept component
    touched = np.zeros(c, dtype=bool)
    into[leaves.to_clip[inside[leaves.from_clip]]] = True
    out_of[leaves.from_clip[inside[leaves.to_clip]]] = True
    touched[leaves.from_clip[other]] = True
    touched[leaves.to_clip[other]] = True
    dropped: list[dict[str, Any]] = []
    for k in np.flatnonzero(~inside):
        group = int(size_clips[label[k]])
        if not touched[k]:
            why = "no transition below tau to or from any other clip"
        elif into[k]:
            why = "dead end: the main component leads into it, but no transition leads back"
        elif out_of[k]:
            why = "unreachable: it leads into the main component, but no transition from there leads to it"
        else:
            why = "no transition to or from the main component"
        if group > 1:
            why += f" (nor for the {group - 1} other clip(s) of its strongly connected group)"
        dropped.append({"clip": names[k], "frames": int(frames[k]), "reason": why})
    return keep, dropped


def moving_frames(tracks: RootTracks, fps: float) -> IntArray:
    """``(C,)`` frames of each clip whose body travels over the floor faster than
    :data:`LOCOMOTION_SPEED` (speed from the root track's consecutive frames)."""
    step = np.linalg.norm(np.diff(tracks.root_xz, axis=0), axis=1) * fps
    fast = np.concatenate((step > LOCOMOTION_SPEED, [False]))
    fast[tracks.offsets[1:-1] - 1] = False  # no step across clips
    clip = np.repeat(np.arange(tracks.offsets.size - 1), np.diff(tracks.offsets))
    return np.bincount(clip, fast, tracks.offsets.size - 1).astype(np.int64)


def dead_end_edges(leaves: LeafEdges, frames: IntArray) -> int:
    """Edges after which the clip they enter has no further edge (playing on reaches its end)."""
    if leaves.size == 0:
        return 0
    last_exit = np.full(frames.size, -1, dtype=np.int64)
    np.maximum.at(last_exit, leaves.from_clip, leaves.from_frame)
    return int(np.count_nonzero(leaves.to_frame > last_exit[leaves.to_clip]))


def build_graph(
    spec: GraphDatabaseSpec,
    library: MotionLibrary,
    emit: Emitter,
    should_stop: ShouldStop,
    *,
    tile: int = TILE,
    workers: int | None = None,
) -> Arrays:
    """The graph arrays of a database: :meth:`EdgeTree.to_arrays` + :meth:`RootTracks.to_arrays` +
    :meth:`FootContacts.to_arrays` (per-frame foot contacts, for foot-skate cleanup) +
    ``graph.report`` (0-d unicode JSON: frames, clips, leaf/root edges, tree nodes, dropped clips
    and why, timings).

    ``emit.progress(fraction, message)`` reports progress (per tile row of the cost matrix);
    ``should_stop()`` is polled per tile and raises :class:`InterruptedError` ("build cancelled").
    Raises :class:`EngineError` for bad settings or when no edge survives.
    """
    t0 = time.perf_counter()
    if tile < 16:
        raise EngineError(f"tile must be >= 16 frames, got {tile}")
    frames = np.array([m.num_frames for m in library.motions], dtype=np.int64)

    def progress(fraction: float, message: str) -> None:
        emit.progress(float(min(max(fraction, 0.0), 1.0)), message)

    progress(0.0, f"graph: features of {int(frames.sum())} frames in {frames.size} clips")
    positions = [m.global_positions() for m in library.motions]
    features = transition_features(library, spec.joint_weights, spec.velocity_weight, positions)
    tracks = root_tracks(library, positions)
    contacts = foot_contacts(library, positions)
    del positions
    t_features = time.perf_counter() - t0
    if should_stop():
        raise InterruptedError("build cancelled")

    screen = screen_rows(features)
    index = (
        frame_index(screen, workers=max(1, workers or _cpu_count()))
        if use_index(spec.candidates, int(frames.sum()))
        else None
    )
    leaves, stats = candidate_edges(
        features,
        spec.tau,
        spec.min_jump_frames,
        method=spec.candidates,
        tile=tile,
        screen=screen,
        index=index,
        workers=workers,
        progress=lambda f, m: progress(0.05 + 0.8 * f, m),
        should_stop=should_stop,
    )
    t_scan = time.perf_counter() - t0 - t_features
    if leaves.size == 0:
        raise EngineError(
            f"no transitions below tau={spec.tau:g} between any frames of the {frames.size} clips; "
            "raise tau (e.g. to 2-4) or add clips of similar motion"
        )
    moving = moving_frames(tracks, library.fps)
    keep, dropped = largest_component(leaves, frames, library.names, moving)
    bridged = 0
    if isinstance(stats, IndexStats) and any(
        d["reason"].startswith(("dead end", "unreachable")) for d in dropped
    ):
        # the index is approximate: look again, harder, for transitions of the clips left out
        # (only clips with transitions one way: a clip without any, or a group apart, is the data)
        position = {name: i for i, name in enumerate(library.names)}
        one_way = [d["clip"] for d in dropped if d["reason"].startswith(("dead end", "unreachable"))]
        out = np.array([position[c] for c in one_way], dtype=np.int64)
        progress(0.86, f"graph: looking again for transitions of {out.size} clips left out")
        extra = bridge_edges(
            features,
            screen,
            out,
            spec.tau,
            spec.min_jump_frames,
            index=index,
            workers=workers,
            should_stop=should_stop,
        )
        if extra.size:
            leaves = merge_edges(leaves, extra)
            keep, again = largest_component(leaves, frames, library.names, moving)
            bridged = len(dropped) - len(again)
            dropped = again
    del screen, index
    kept = leaves.take(keep)
    if kept.size == 0:
        raise EngineError(
            f"the {leaves.size} transitions below tau={spec.tau:g} form no cycle between clips: "
            "every path reaches a clip's end; raise tau or add clips that lead back to each other"
        )
    position = {name: i for i, name in enumerate(library.names)}
    dropped_index = np.array([position[d["clip"]] for d in dropped], dtype=np.int64)
    dropped_frames = int(frames[dropped_index].sum())
    progress(0.92, f"graph: hierarchy of {kept.size} edges")
    tree = build_hierarchy(kept)
    if should_stop():
        raise InterruptedError("build cancelled")
    elapsed = time.perf_counter() - t0
    report = {
        "frames": int(frames.sum()),
        "clips": int(frames.size),
        "fps": library.fps,
        "tau": spec.tau,
        "leaf_edges": kept.size,
        "root_edges": int(tree.roots.size),
        "tree_nodes": tree.size,
        "candidate_edges": leaves.size,
        "dead_end_edges": dead_end_edges(kept, frames),
        "dropped_clips": dropped,
        "kept": {
            "clips": int(frames.size) - len(dropped),
            "frames": int(frames.sum()) - dropped_frames,
            "moving_frames": int(moving.sum()) - int(moving[dropped_index].sum()),
        },
        "dropped_frames": dropped_frames,
        "bridged_clips": bridged,
        "joint_weights": dict(zip(features.joints, features.joint_weights.tolist(), strict=True)),
        "feature_dims": int(features.rows.shape[1]),
        "scan_dims": stats.dims,
        "candidates": "indexed" if isinstance(stats, IndexStats) else "all_pairs",
        **(
            {"index_cells": stats.cells, "index_probed": stats.probed, "seeds": stats.seeds}
            if isinstance(stats, IndexStats)
            else {"below_tau": stats.below_tau}
        ),
        "max_steps": features.max_steps,
        "features_s": round(t_features, 3),
        "scan_s": round(t_scan, 3),
        "build_s": round(elapsed, 3),
    }
    progress(1.0, f"graph: {kept.size} edges, {tree.roots.size} roots, {len(dropped)} clips dropped")
    arrays: Arrays = {}
    arrays.update(tree.to_arrays())
    arrays.update(tracks.to_arrays())
    arrays.update(contacts.to_arrays())
    arrays["graph.report"] = np.array(json.dumps(report))
    return arrays
