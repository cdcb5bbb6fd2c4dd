"""Paths through the hierarchical motion graph, the pieces they play and where those pieces go.

A :class:`Path` is a start ``(clip, frame)`` and a sequence of edge ids (any node of the
:class:`~engines.graph.model.EdgeTree`, roots or finer). It plays the start clip from the start
frame up to and including ``from_frame[e_1]``, continues in ``to_clip[e_1]`` at ``to_frame[e_1]``
up to ``from_frame[e_2]``, and so on; the last piece plays to the end of its clip. It is valid
when ``from_clip[e_1] == start clip``, ``from_frame[e_1] >= start frame`` and, for consecutive
edges, ``to_clip[e_i] == from_clip[e_{i+1}]`` and ``to_frame[e_i] <= from_frame[e_{i+1}]``.
The output is the first ``length`` frames of what the path plays (the last piece is truncated); a
path that plays fewer frames is too short (the score penalises it).

Floor placement (2-D rigid transforms)
    A transform ``(theta, shift)`` maps a floor point ``p = [x, z]`` to ``R(theta) p + shift`` with
    ``R(theta) [x, z] = [cos x + sin z, -sin x + cos z]``: a rotation about +Y by ``theta`` radians
    (the convention of :func:`motion.align.apply_rigid_2d` and :func:`motion.rotations.from_yaw`;
    it adds ``theta`` to a heading). The ground frame ``G(c, f)`` of a clip frame is the transform
    ``(root_yaw, root_xz)`` of :class:`~engines.graph.model.RootTracks` (body -> clip coordinates).

    Piece ``j`` is placed by ``T_j`` (clip -> output coordinates) so that its first frame lands
    where the previous piece's next frame would have been: ``T_j = T_{j-1} o D(e_j)`` with the
    edge transform ``D(e) = G(from_clip, from_frame + 1) o G(to_clip, to_frame)^-1`` (the step past
    a clip's last frame is extrapolated from its last step). ``D`` is precomputed for every edge,
    so placing a path is ``O(pieces)``, and is done for a whole batch of paths at once.

Batches
    :class:`PathBatch` holds ``B`` paths as padded arrays; :func:`batch_pieces`,
    :func:`batch_valid`, :func:`batch_transforms` and :func:`locate` work on all of them at once
    (``(B, M + 1)`` piece arrays, ``M`` the longest edge list), which is how the search scores
    thousands of mutations per step.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from cachetools import LRUCache, cached

from motion.kinematics import forward_kinematics
from motion.rotations import rotate_floor

from ..library import MotionLibrary
from .model import EdgeTree, FloatArray, IntArray, RootTracks

BoolArray = npt.NDArray[np.bool_]

# -- 2-D rigid transforms on the floor ---------------------------------------------------------


def compose2(
    a_theta: FloatArray | float, a_shift: FloatArray, b_theta: FloatArray | float, b_shift: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``a o b`` (apply ``b`` first): ``(a_theta + b_theta, R(a_theta) b_shift + a_shift)``."""
    return np.asarray(a_theta + np.asarray(b_theta)), rotate_floor(a_theta, b_shift) + a_shift


def invert2(theta: FloatArray | float, shift: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Inverse transform: ``(-theta, -R(-theta) shift)``."""
    th = -np.asarray(theta, dtype=np.float64)
    return th, -rotate_floor(th, shift)


# -- paths -------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Path:
    """A start ``(clip, frame)`` and the edge ids taken from there (see the module docstring)."""

    start_clip: int
    start_frame: int
    edges: tuple[int, ...] = ()

    @property
    def key(self) -> tuple[int, int, tuple[int, ...]]:
        return (self.start_clip, self.start_frame, self.edges)


@dataclass(frozen=True, slots=True)
class Pieces:
    """The pieces a path plays within the output, ``(P,)`` arrays.

    Attributes
    ----------
    clip, first, last:
        Clip index and first/last source frame (inclusive) of each piece; the last piece is
        truncated to the requested length.
    start:
        Output frame of each piece's first frame (``start[0] == 0``).
    total:
        Frames the untruncated path plays (``< length`` when the path is too short).
    """

    clip: IntArray
    first: IntArray
    last: IntArray
    start: IntArray
    total: int

    @property
    def count(self) -> IntArray:
        """``(P,)`` frames of each piece."""
        return np.asarray(self.last - self.first + 1, dtype=np.int64)

    @property
    def frames(self) -> int:
        """Output frames (``min(total, length)``)."""
        return int(self.count.sum())

    def source(self) -> tuple[IntArray, IntArray]:
        """``(F,)`` source clip and frame of every output frame."""
        counts = self.count
        clips = np.repeat(self.clip, counts)
        offsets = np.arange(int(counts.sum())) - np.repeat(self.start, counts)
        return clips, np.repeat(self.first, counts) + offsets


@dataclass(frozen=True, slots=True)
class Placement:
    """Per piece, the 2-D transform (clip -> output floor coordinates): ``theta (P,)`` radians,
    ``shift (P, 2)`` metres; with the pieces and the root tracks it gives the root's floor
    position and heading at any output frame (:meth:`root`)."""

    theta: FloatArray
    shift: FloatArray
    pieces: Pieces
    tracks: RootTracks

    def root(self, frames: IntArray | list[int]) -> tuple[FloatArray, FloatArray]:
        """Root floor position ``(K, 2)`` metres and heading ``(K,)`` radians at output frames."""
        t = np.clip(np.asarray(frames, dtype=np.int64), 0, max(self.pieces.frames - 1, 0))
        j = np.searchsorted(self.pieces.start, t, side="right") - 1
        rows = self.tracks.offsets[self.pieces.clip[j]] + self.pieces.first[j] + (t - self.pieces.start[j])
        yaw = self.theta[j] + self.tracks.root_yaw[rows]
        xz = rotate_floor(self.theta[j], self.tracks.root_xz[rows]) + self.shift[j]
        return xz, yaw

    def per_frame(self) -> tuple[FloatArray, FloatArray]:
        """``(F,)`` theta and ``(F, 2)`` shift of the transform of every output frame."""
        counts = self.pieces.count
        return np.repeat(self.theta, counts), np.repeat(self.shift, counts, axis=0)


EDGE_BLOCK = 1 << 18
"""Edges whose transforms :class:`GraphIndex` computes at once (about 130 bytes of temporaries an
edge: 34 MB a block, where all at once took 1 GB at 1M frames)."""


class GraphIndex:
    """What the search precomputes from an edge tree and the root tracks.

    Attributes
    ----------
    tree, tracks:
        The graph (see :mod:`engines.graph.model`).
    frames:
        ``(C,)`` frames per clip.
    edge_theta, edge_shift:
        ``(E,)`` and ``(E, 2)``: the edge transform ``D(e)`` of every edge (module docstring).
    roots:
        Edge ids of the coarsest graph G', sorted by (from clip, from frame).
    """

    def __init__(self, tree: EdgeTree, tracks: RootTracks) -> None:
        self.tree = tree
        self.tracks = tracks
        self.frames = np.diff(tracks.offsets).astype(np.int64)
        n_clips = self.frames.size
        if tracks.root_xz.shape != (int(tracks.offsets[-1]), 2) or tracks.root_yaw.shape != (
            int(tracks.offsets[-1]),
        ):
            raise ValueError("root tracks disagree with their offsets")
        if tree.size:
            for clip, frame in ((tree.from_clip, tree.from_frame), (tree.to_clip, tree.to_frame)):
                if clip.min() < 0 or clip.max() >= n_clips:
                    raise ValueError("edges name clips outside the tracks")
                if frame.min() < 0 or np.any(frame >= self.frames[clip]):
                    raise ValueError("edges name frames outside their clips")
        self.n_clips = n_clips
        self.root_x = np.ascontiguousarray(tracks.root_xz[:, 0])
        self.root_z = np.ascontiguousarray(tracks.root_xz[:, 1])
        # the edge transforms, padded (one identity transform at index E, for -1 pads), as 1-D
        # arrays: gathers from 1-D arrays are several times faster than from (E, 2) ones. Only
        # these are kept (40 bytes an edge): edge_theta / edge_shift are read from them
        self.pad_theta, self.pad_turn, self.pad_shift = self._edge_transforms()
        roots = tree.roots
        order = np.lexsort((tree.from_frame[roots], tree.from_clip[roots]))
        self.roots = roots[order]
        rc = tree.from_clip[self.roots]
        self._root_start = np.searchsorted(rc, np.arange(n_clips + 1))
        self._root_frames = tree.from_frame[self.roots]  # stored dtype: int32 when loaded
        self._pair: dict[tuple[int, int], IntArray] = {}
        self._two: dict[tuple[int, int], tuple[IntArray, IntArray]] = {}
        self._span = int(tree.from_frame.max(initial=0)) + int(tree.to_frame.max(initial=0)) + 2
        self._root_keys: IntArray | None = None  # clip * _span + from frame of roots, built on first use

    @property
    def edge_theta(self) -> FloatArray:
        """``(E,)`` the rotation of every edge transform ``D(e)`` (radians; a view)."""
        return self.pad_theta[:-1]

    @property
    def edge_shift(self) -> FloatArray:
        """``(E, 2)`` the shift of every edge transform ``D(e)`` (metres; a new array)."""
        return np.stack((self.pad_shift.real[:-1], self.pad_shift.imag[:-1]), axis=-1)

    @staticmethod
    @cached(LRUCache(maxsize=4), key=lambda tree, tracks: (id(tree), id(tracks)), lock=threading.Lock())
    def of(tree: EdgeTree, tracks: RootTracks) -> GraphIndex:
        """The index of a graph, cached for the last few graphs (by identity: a loaded engine
        keeps its tree and tracks, so its searches share one index; a cached index holds its tree
        and tracks, so their ids are not reused while it is cached)."""
        return GraphIndex(tree, tracks)

    # ground frames
    def ground(self, clip: IntArray, frame: IntArray) -> tuple[FloatArray, FloatArray]:
        """Ground frame ``G(c, f)`` (yaw radians, floor position metres) of clip frames."""
        rows = self.tracks.offsets[clip] + frame
        return self.tracks.root_yaw[rows], np.stack((self.root_x[rows], self.root_z[rows]), axis=-1)

    def _frame_transforms(self) -> tuple[FloatArray, npt.NDArray[np.complex128], npt.NDArray[np.complex128]]:
        """Per library frame ``g``, ``G(c, f + 1)`` (extrapolated by one step past a clip's last
        frame) as angle ``(N,)``, rotation ``exp(-i angle)`` and complex shift ``x + i z``."""
        off = self.tracks.offsets
        n = int(off[-1])
        yaw = self.tracks.root_yaw
        z = self.root_x + 1j * self.root_z
        last = np.zeros(n, dtype=bool)
        last[off[1:][self.frames > 0] - 1] = True
        nxt = np.minimum(np.arange(n) + 1, n - 1)
        ang = yaw[nxt].copy()
        pos = z[nxt].copy()
        if np.any(last):
            g = np.flatnonzero(last)
            first = np.zeros(n, dtype=bool)
            first[off[:-1][self.frames > 0]] = True
            prev = np.where(first[g], g, g - 1)
            # G(f) o (G(f-1)^-1 o G(f)): the last step repeated
            step_ang = yaw[g] - yaw[prev]
            step_pos = np.exp(1j * yaw[prev]) * (z[g] - z[prev])
            ang[g] = yaw[g] + step_ang
            pos[g] = np.exp(-1j * yaw[g]) * step_pos + z[g]
        return ang, np.exp(-1j * ang), pos

    def _edge_transforms(self) -> tuple[FloatArray, npt.NDArray[np.complex128], npt.NDArray[np.complex128]]:
        """``D(e) = G(from_clip, from_frame + 1) o G(to_clip, to_frame)^-1`` for every edge, padded
        with the identity at index E: ``(E + 1,)`` angle, rotation ``exp(-i angle)`` and shift
        ``x + i z``. Computed :data:`EDGE_BLOCK` edges at a time (element by element the same
        numbers as all at once), so the load's temporaries stay small."""
        t = self.tree
        theta = np.zeros(t.size + 1)
        shift = np.zeros(t.size + 1, dtype=np.complex128)
        if t.size:
            ang, turn, pos = self._frame_transforms()
            off = self.tracks.offsets
            for lo in range(0, t.size, EDGE_BLOCK):
                s = slice(lo, min(lo + EDGE_BLOCK, t.size))
                gf = off[t.from_clip[s]] + t.from_frame[s]
                gt = off[t.to_clip[s]] + t.to_frame[s]
                yaw_t = self.tracks.root_yaw[gt]
                z_t = self.root_x[gt] + 1j * self.root_z[gt]
                # G^-1 = (-yaw, -R(-yaw) z); a o b = (a + b, R(a) b_shift + a_shift)
                inv_shift = -np.exp(1j * yaw_t) * z_t
                theta[s] = ang[gf] - yaw_t
                z_e = turn[gf] * inv_shift + pos[gf]
                # x + i z from the parts, as the (E, 2) shifts were joined (the same signed zeros)
                shift[s] = z_e.real + 1j * z_e.imag
        return theta, np.exp(-1j * theta), shift

    # edge lookups
    def root_out(self, clip: int, min_from_frame: int = 0) -> IntArray:
        """Root edges leaving ``clip`` at ``from_frame >= min_from_frame``, by from frame."""
        lo, hi = int(self._root_start[clip]), int(self._root_start[clip + 1])
        # a key of the frames' own dtype (clamped into its range: the same answer), so that
        # searchsorted does not cast the frames to int64
        info = np.iinfo(self._root_frames.dtype)
        key = self._root_frames.dtype.type(min(max(min_from_frame, info.min), info.max))
        k = int(np.searchsorted(self._root_frames[lo:hi], key, side="left"))
        return self.roots[lo + k : hi]

    def root_pair(self, a: int, b: int) -> IntArray:
        """Root edges from clip ``a`` to clip ``b`` (cached)."""
        got = self._pair.get((a, b))
        if got is None:
            out = self.root_out(a)
            got = out[self.tree.to_clip[out] == b]
            self._pair[(a, b)] = got
        return got

    def two_hops(self, a: int, b: int) -> tuple[IntArray, IntArray]:
        """All valid root-edge pairs ``(h1, h2)`` from clip ``a`` through any clip to clip ``b``
        (``to_frame[h1] <= from_frame[h2]``), cached per ``(a, b)``; ``b = -1`` for any clip."""
        got = self._two.get((a, b))
        if got is not None:
            return got
        t = self.tree
        out_a = self.root_out(a)
        if b < 0:
            got = self._two_hops_any(out_a)
            self._two[(a, b)] = got
            return got
        first: list[IntArray] = []
        second: list[IntArray] = []
        for mid in np.unique(t.to_clip[out_a]):
            h1 = out_a[t.to_clip[out_a] == mid]
            h2 = self.root_out(int(mid)) if b < 0 else self.root_pair(int(mid), b)
            if h1.size == 0 or h2.size == 0:
                continue
            ok = t.to_frame[h1][:, None] <= t.from_frame[h2][None, :]
            i, k = np.nonzero(ok)
            first.append(h1[i])
            second.append(h2[k])
        got = (
            (np.concatenate(first), np.concatenate(second))
            if first
            else (np.zeros(0, np.int64), np.zeros(0, np.int64))
        )
        self._two[(a, b)] = got
        return got

    def _two_hops_any(self, out_a: IntArray) -> tuple[IntArray, IntArray]:
        """``two_hops(a, -1)`` without a loop over the middle clips: the second edges of a first
        edge ``h1`` are the root edges of ``to_clip[h1]`` from ``to_frame[h1]`` on, a contiguous
        run of :attr:`roots` (sorted by clip, then from frame). Same pairs in the same order as
        the per-clip tables (middle clips ascending, then ``h1`` in ``out_a`` order, then ``h2``
        by from frame), a few times faster when a large library's copies give a clip thousands
        of edges."""
        t = self.tree
        h1 = out_a[np.argsort(t.to_clip[out_a], kind="stable")]
        if self._root_keys is None:
            self._root_keys = t.from_clip[self.roots].astype(np.int64) * self._span + t.from_frame[self.roots]
        mid = t.to_clip[h1].astype(np.int64)
        lo = np.searchsorted(self._root_keys, mid * self._span + t.to_frame[h1], side="left")
        hi = self._root_start[mid + 1]
        count = np.maximum(hi - lo, 0)
        total = int(count.sum())
        first = np.repeat(h1, count)
        # positions lo, lo + 1, ..., hi - 1 for each h1, concatenated
        starts = np.repeat(lo - (np.cumsum(count) - count), count)
        second = self.roots[starts + np.arange(total)]
        return first, second


# -- batches -----------------------------------------------------------------------------------


@dataclass(slots=True)
class PathBatch:
    """``B`` paths as arrays: ``start_clip (B,)``, ``start_frame (B,)``, ``edges (B, M)`` (-1 pads)."""

    start_clip: IntArray
    start_frame: IntArray
    edges: IntArray

    @property
    def size(self) -> int:
        return int(self.start_clip.size)

    @property
    def n_edges(self) -> IntArray:
        return np.asarray((self.edges >= 0).sum(axis=1), dtype=np.int64)

    @classmethod
    def from_paths(cls, paths: list[Path]) -> PathBatch:
        m = max((len(p.edges) for p in paths), default=0)
        edges = np.full((len(paths), m), -1, dtype=np.int64)
        for i, p in enumerate(paths):
            edges[i, : len(p.edges)] = p.edges
        return cls(
            np.array([p.start_clip for p in paths], dtype=np.int64),
            np.array([p.start_frame for p in paths], dtype=np.int64),
            edges,
        )

    def path(self, i: int) -> Path:
        row = self.edges[i]
        return Path(int(self.start_clip[i]), int(self.start_frame[i]), tuple(int(e) for e in row[row >= 0]))

    def take(self, idx: IntArray) -> PathBatch:
        sub = PathBatch(self.start_clip[idx], self.start_frame[idx], self.edges[idx])
        m = int(sub.n_edges.max(initial=0))
        sub.edges = sub.edges[:, :m]
        return sub

    @staticmethod
    def concat(batches: list[PathBatch]) -> PathBatch:
        if not batches:  # e.g. a path with no mutation at all: an empty batch
            empty = np.zeros(0, dtype=np.int64)
            return PathBatch(empty, empty.copy(), np.zeros((0, 0), dtype=np.int64))
        m = max((b.edges.shape[1] for b in batches), default=0)
        padded = [np.pad(b.edges, ((0, 0), (0, m - b.edges.shape[1])), constant_values=-1) for b in batches]
        return PathBatch(
            np.concatenate([b.start_clip for b in batches]),
            np.concatenate([b.start_frame for b in batches]),
            np.concatenate(padded) if padded else np.zeros((0, 0), np.int64),
        )


@dataclass(slots=True)
class BatchPieces:
    """Pieces of a batch, ``(B, M + 1)`` arrays; unused slots have ``count == 0``.

    ``start`` is the output frame of each piece's first frame, ``total (B,)`` the frames each
    (untruncated) path plays."""

    clip: IntArray
    first: IntArray
    last: IntArray
    count: IntArray
    start: IntArray
    total: IntArray


def batch_valid(index: GraphIndex, batch: PathBatch) -> BoolArray:
    """``(B,)`` whether each path is valid (edge chaining and start, module docstring)."""
    t = index.tree
    e = batch.edges
    ok = (batch.start_clip >= 0) & (batch.start_clip < index.n_clips) & (batch.start_frame >= 0)
    ok &= batch.start_frame < index.frames[np.clip(batch.start_clip, 0, index.n_clips - 1)]
    if e.shape[1] == 0:
        return np.asarray(ok)
    used = e >= 0
    # pads only at the end
    ok &= ~np.any(~used[:, :-1] & used[:, 1:], axis=1)
    safe = np.where(used, e, 0)
    first = safe[:, 0]
    ok &= ~used[:, 0] | (
        (t.from_clip[first] == batch.start_clip) & (t.from_frame[first] >= batch.start_frame)
    )
    if e.shape[1] > 1:
        a, b = safe[:, :-1], safe[:, 1:]
        link = (t.to_clip[a] == t.from_clip[b]) & (t.to_frame[a] <= t.from_frame[b])
        ok &= np.all(link | ~used[:, 1:], axis=1)
    return np.asarray(ok)


def batch_pieces(index: GraphIndex, batch: PathBatch, length: int) -> BatchPieces:
    """Pieces of every path of a (valid) batch, truncated to ``length`` output frames."""
    t = index.tree
    e = batch.edges
    b, m = e.shape
    used = e >= 0
    n = used.sum(axis=1)
    safe = np.where(used, e, 0)
    clip = np.empty((b, m + 1), dtype=np.int64)
    first = np.empty((b, m + 1), dtype=np.int64)
    last = np.empty((b, m + 1), dtype=np.int64)
    clip[:, 0] = batch.start_clip
    first[:, 0] = batch.start_frame
    clip[:, 1:] = t.to_clip[safe]
    first[:, 1:] = t.to_frame[safe]
    last[:, :m] = t.from_frame[safe]
    last[:, m] = 0
    # the piece after the last edge plays to its clip's end
    rows = np.arange(b)
    last[rows, n] = index.frames[clip[rows, n]] - 1
    live = np.arange(m + 1)[None, :] <= n[:, None]
    full = np.where(live, last - first + 1, 0)
    start = np.zeros((b, m + 1), dtype=np.int64)
    np.cumsum(full[:, :-1], axis=1, out=start[:, 1:])
    total = full.sum(axis=1)
    count = np.clip(np.minimum(full, length - start), 0, None)
    return BatchPieces(clip, first, first + count - 1, count, start, total)


def batch_transforms(index: GraphIndex, batch: PathBatch) -> tuple[FloatArray, FloatArray]:
    """``theta (B, M + 1)`` and ``shift (B, M + 1, 2)``: the placement ``T_j`` of every piece,
    with the start frame's ground frame at the origin facing +Z (before any anchoring).

    With floor vectors as complex numbers ``x + i z``, ``R(theta)`` is a product by
    ``exp(-i theta)``, so ``T_j = T_{j-1} o D(e_j)`` unrolls into a cumulative product (the
    rotations) and cumulative sums (angles, shifts): no loop over pieces, no trigonometry."""
    e = batch.edges
    b, m = e.shape
    th0, sh0 = invert2(*index.ground(batch.start_clip, batch.start_frame))
    ej = np.where(e >= 0, e, index.tree.size)  # pads -> the identity transform at the end
    theta = np.empty((b, m + 1))
    theta[:, 0] = th0
    np.cumsum(index.pad_theta[ej], axis=1, out=theta[:, 1:])
    theta[:, 1:] += th0[:, None]
    turn = np.empty((b, m + 1), dtype=np.complex128)
    turn[:, 0] = np.exp(-1j * th0)
    np.cumprod(index.pad_turn[ej], axis=1, out=turn[:, 1:])
    turn[:, 1:] *= turn[:, :1]
    z = np.empty((b, m + 1), dtype=np.complex128)
    z[:, 0] = sh0[:, 0] + 1j * sh0[:, 1]
    np.cumsum(turn[:, :-1] * index.pad_shift[ej], axis=1, out=z[:, 1:])
    z[:, 1:] += z[:, :1]
    return theta, np.stack((z.real, z.imag), axis=-1)


def locate(pieces: BatchPieces, t: int) -> tuple[IntArray, IntArray, IntArray]:
    """Piece index, clip and source frame ``(B,)`` shown at output frame ``t`` (clamped to each
    path's last output frame)."""
    frames = pieces.count.sum(axis=1)
    tt = np.minimum(t, np.maximum(frames - 1, 0))
    j = (pieces.start <= tt[:, None]).sum(axis=1) - 1
    # pieces of zero frames share their start with the next one: skip back to a live piece
    j = np.minimum(j, np.maximum((pieces.count > 0).sum(axis=1) - 1, 0))
    rows = np.arange(j.size)
    clip = pieces.clip[rows, j]
    frame = pieces.first[rows, j] + (tt - pieces.start[rows, j])
    return j, clip, frame


def path_pieces(index: GraphIndex, path: Path, length: int) -> Pieces:
    """Pieces of one path within ``length`` output frames (empty pieces dropped)."""
    bp = batch_pieces(index, PathBatch.from_paths([path]), length)
    live = bp.count[0] > 0
    live[0] = True
    return Pieces(bp.clip[0][live], bp.first[0][live], bp.last[0][live], bp.start[0][live], int(bp.total[0]))


def trim(index: GraphIndex, path: Path, length: int) -> Path:
    """The path without the edges whose pieces start at or after ``length`` output frames."""
    bp = batch_pieces(index, PathBatch.from_paths([path]), length)
    keep = int(np.count_nonzero(bp.start[0, 1 : len(path.edges) + 1] < length))
    return Path(path.start_clip, path.start_frame, path.edges[:keep])


def clip_sequence(index: GraphIndex, path: Path, length: int) -> tuple[int, ...]:
    """The clips of a path's pieces within ``length`` frames (what makes alternatives distinct)."""
    return tuple(int(c) for c in path_pieces(index, path, length).clip)


# -- joint positions ---------------------------------------------------------------------------


class JointTable:
    """Global joint positions of library frames (metres, clip coordinates), computed per clip on
    first use (one forward-kinematics pass per clip) and kept for the joints asked for.

    ``at(clip, frame)`` gathers ``(..., K, 3)`` positions of the table's ``K`` joints.
    """

    def __init__(self, library: MotionLibrary, tracks: RootTracks, joints: list[int]) -> None:
        self.library = library
        self.offsets = tracks.offsets
        self.joints = np.asarray(joints, dtype=np.intp)
        n = int(tracks.offsets[-1])
        self._pos = np.zeros((n, self.joints.size, 3))
        self._done = np.zeros(self.offsets.size - 1, dtype=bool)

    def _fill(self, clip: int) -> None:
        m = self.library.motions[clip]
        sk = m.skeleton
        if sk.translated_joints.size:
            pos, _ = forward_kinematics(sk.parents, m.local_translations(), m.rotations, with_rotations=False)
        else:
            pos, _ = forward_kinematics(
                sk.parents, sk.offsets, m.rotations, root_positions=m.root_positions, with_rotations=False
            )
        lo = int(self.offsets[clip])
        self._pos[lo : lo + m.num_frames] = pos[:, self.joints] * m.metres_per_unit
        self._done[clip] = True

    def at(self, clip: IntArray, frame: IntArray) -> FloatArray:
        """Positions ``(..., K, 3)`` of the table's joints at clip frames (arrays of one shape)."""
        need = np.unique(clip)
        for c in need[~self._done[need]]:
            self._fill(int(c))
        return np.asarray(self._pos[self.offsets[clip] + frame])

    def velocity(self, clip: IntArray, frame: IntArray, fps: float) -> FloatArray:
        """Velocities ``(..., K, 3)`` m/s by central differences within each clip (one-sided at
        the clip's ends)."""
        n = np.diff(self.offsets)[clip]
        a = np.maximum(frame - 1, 0)
        b = np.minimum(frame + 1, n - 1)
        span = np.maximum(b - a, 1)[..., None, None]
        return np.asarray((self.at(clip, b) - self.at(clip, a)) * fps / span)
