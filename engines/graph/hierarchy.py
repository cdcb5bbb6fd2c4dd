"""The edge hierarchy: tree-structured vector quantization of each clip pair's edges (Sec. 4.1).

Arikan & Forsyth (2002) summarise the graph G by clustering, for every ordered pair of clips
``(s, t)``, its edges by their ``(fromFrame, toFrame)`` labels with k-means, the number of clusters
being the major/minor axis ratio of the ellipse fitted to the edges (PCA); the cluster centres
(mean from frame, to frame and cost) are the edges of the coarsest graph G', and each cluster is
split in two recursively with k-means down to single edges (TSVQ), giving a binary tree per root.

Choices where the paper leaves room (documented so the search can rely on them):

* Edges of a clip to itself are split first into forward and backward jumps and clustered
  separately: their union is symmetric about the diagonal, and its mean would be a useless cut
  to the next frame.
* ``k = round(major / max(minor, 1 frame))``, clamped to ``[1, ceil(sqrt(n))]`` for ``n`` edges: the
  local-minimum edges of the build are isolated points, and on a nearly collinear set the plain
  ratio would make every edge a root (no hierarchy at all).
* k-means and the 2-means splits are small vectorised Lloyd iterations run on all clip pairs (and
  all clusters of one tree level) at once, initialised deterministically along the major axis
  (quantiles; the median for a split). Calling a library k-means once per pair and per split costs
  ~1 ms a call, which is minutes for 10^5 edges. A group of at most :data:`SMALL_GROUP` edges gets
  its whole subtree at once by median splits of its edges sorted along its major axis (the axis is
  not refitted for its halves), and splits deeper than :data:`MAX_KMEANS_DEPTH` levels use the
  median alone: both are balanced and bound the tree depth.
* Means are rounded, so an internal edge of a clip to itself may jump one frame less than
  ``min_jump_frames`` (its leaves all respect it).

Frames are in database frames; internal nodes carry the mean from/to frame of the leaves below them,
rounded half up (:func:`round_frames`), and their mean cost.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .model import EdgeTree

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

SMALL_GROUP = 8
"""Groups of at most this many edges are split at the median of their major axis (no k-means)."""
MAX_KMEANS_DEPTH = 32
"""Splits deeper than this use the median only (bounds the depth at 32 + log2(n))."""
LLOYD_ITERATIONS = 5
"""Lloyd iterations of the k-means steps (initialised along the major axis, they settle fast)."""


@dataclass(frozen=True, slots=True)
class LeafEdges:
    """Edges of the full graph G, ``(E,)`` arrays (semantics of :mod:`engines.graph.model`)."""

    from_clip: IntArray
    from_frame: IntArray
    to_clip: IntArray
    to_frame: IntArray
    cost: FloatArray

    @property
    def size(self) -> int:
        return int(self.from_clip.size)

    def take(self, index: npt.NDArray[np.intp] | BoolArray) -> LeafEdges:
        """The edges selected by an index array or a boolean mask."""
        return LeafEdges(
            self.from_clip[index],
            self.from_frame[index],
            self.to_clip[index],
            self.to_frame[index],
            self.cost[index],
        )

    @classmethod
    def empty(cls) -> LeafEdges:
        z = np.zeros(0, dtype=np.int64)
        return cls(z, z.copy(), z.copy(), z.copy(), np.zeros(0))


def _wsum(labels: IntArray, weights: npt.ArrayLike, size: int) -> FloatArray:
    """Per label ``0 .. size-1``, the sum of ``weights`` (float64)."""
    return np.bincount(labels, weights, size).astype(np.float64, copy=False)


def round_frames(mean: FloatArray) -> IntArray:
    """Mean frames rounded half up (``10.5 -> 11``), as internal nodes store them."""
    return np.floor(np.asarray(mean, dtype=np.float64) + 0.5).astype(np.int64)


def _group_stats(
    g: IntArray, pts: FloatArray, n_groups: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per group of 2-D points: count ``(G,)``, mean ``(G, 2)``, major axis ``(G, 2)`` (unit) and the
    axis standard deviations ``(G, 2)`` (major, minor)."""
    n = np.bincount(g, minlength=n_groups).astype(np.float64)
    safe = np.maximum(n, 1.0)
    mean = np.stack([_wsum(g, pts[:, i], n_groups) / safe for i in range(2)], axis=1)
    d = pts - mean[g]
    a = _wsum(g, d[:, 0] * d[:, 0], n_groups) / safe
    b = _wsum(g, d[:, 0] * d[:, 1], n_groups) / safe
    c = _wsum(g, d[:, 1] * d[:, 1], n_groups) / safe
    theta = 0.5 * np.arctan2(2.0 * b, a - c)
    axis = np.stack((np.cos(theta), np.sin(theta)), axis=1)
    half_sum, root = 0.5 * (a + c), np.sqrt((0.5 * (a - c)) ** 2 + b**2)
    std = np.sqrt(np.clip(np.stack((half_sum + root, half_sum - root), axis=1), 0.0, None))
    return n, mean, axis, std


def _compact(labels: IntArray, size: int) -> tuple[IntArray, int]:
    """Relabel ``labels`` (values in ``[0, size)``) to ``0 .. m-1`` keeping their order; returns the
    labels and ``m``."""
    present = np.bincount(labels, minlength=size) > 0
    table = np.cumsum(present) - 1
    return table[labels].astype(np.int64), int(present.sum())


def _ranks_along(g: IntArray, proj: FloatArray, n: FloatArray, spread: FloatArray) -> IntArray:
    """Each point's rank ``0 .. n_g - 1`` within its group when sorted by ``proj`` (centred
    projections; ``spread[g] >= max |proj|`` of the group). One float argsort, no lexsort."""
    frac = 0.5 + 0.49 * proj / np.maximum(spread[g], 1e-12)
    order = np.argsort(g + frac, kind="stable")
    starts = np.concatenate(([0], np.cumsum(n.astype(np.int64))[:-1]))
    rank = np.empty(g.size, dtype=np.int64)
    rank[order] = np.arange(g.size, dtype=np.int64) - starts[g[order]]
    return rank


def _major_projection(g: IntArray, pts: FloatArray, n_groups: int) -> tuple[FloatArray, FloatArray, IntArray]:
    """Per group: counts ``(G,)`` and axis deviations ``(G, 2)``; per point: its rank along its
    group's major axis."""
    n, mean, axis, std = _group_stats(g, pts, n_groups)
    proj = np.einsum("ij,ij->i", pts - mean[g], axis[g])
    # sum(proj^2) = n var, so |proj| <= sqrt(n) * std_major
    rank = _ranks_along(g, proj, n, np.sqrt(n) * std[:, 0] * 1.0001 + 1e-9)
    return n, std, rank


def _kmeans_by_group(g: IntArray, pts: FloatArray, n_groups: int) -> tuple[IntArray, int]:
    """Top-level clustering: per group, k-means with ``k`` from the ellipse axis ratio, initialised
    with ``k`` quantile bins along the major axis.

    Returns ``(E,)`` cluster labels ``0 .. m-1`` (clusters never span groups) and ``m``."""
    n, std, rank = _major_projection(g, pts, n_groups)
    ratio = std[:, 0] / np.maximum(std[:, 1], 1.0)
    k = np.clip(np.rint(ratio), 1.0, np.maximum(np.ceil(np.sqrt(n)), 1.0)).astype(np.int64)
    base = np.concatenate(([0], np.cumsum(k)[:-1]))
    total = int(k.sum())
    label = base[g] + (rank * k[g]) // n[g].astype(np.int64)
    sub = np.flatnonzero(k[g] > 1)
    if sub.size:
        sub = sub[np.argsort(-k[g[sub]], kind="stable")]  # points of groups with k > j: a prefix
        k_sub, base_sub, p_sub = k[g[sub]], base[g[sub]], pts[sub]
        prefix = [int(np.count_nonzero(k_sub > j)) for j in range(int(k.max()))]
        lab = label[sub]
        for _ in range(LLOYD_ITERATIONS):
            cnt = np.bincount(lab, minlength=total).astype(np.float64)
            cen = np.stack([_wsum(lab, p_sub[:, i], total) for i in range(2)], axis=1)
            cen = np.where(cnt[:, None] > 0, cen / np.maximum(cnt, 1.0)[:, None], np.inf)
            best = np.full(sub.size, np.inf)
            new = lab.copy()
            for j, m in enumerate(prefix):
                d = np.sum((p_sub[:m] - cen[base_sub[:m] + j]) ** 2, axis=1)
                closer = np.flatnonzero(d < best[:m])
                best[closer] = d[closer]
                new[closer] = base_sub[closer] + j
            if np.array_equal(new, lab):
                break
            lab = new
        label[sub] = lab
    return _compact(label, total)


def _split_in_two(
    g: IntArray, pts: FloatArray, n: FloatArray, rank: IntArray, n_groups: int, kmeans: bool
) -> BoolArray:
    """One TSVQ level: for every group (``n`` points, ``rank`` along its major axis) whether each
    point goes left: the median split, refined by 2-means when ``kmeans``; neither half is ever
    empty."""
    left = rank < (n[g].astype(np.int64) // 2)
    if not kmeans:
        return left
    ref = np.arange(g.size)
    for _ in range(LLOYD_ITERATIONS):
        if ref.size == 0:
            break
        gr, pr, lr = g[ref], pts[ref], left[ref]
        side = 2 * gr + (~lr)
        cnt = np.bincount(side, minlength=2 * n_groups).astype(np.float64)
        cen = np.stack([_wsum(side, pr[:, i], 2 * n_groups) for i in range(2)], axis=1)
        cen /= np.maximum(cnt, 1.0)[:, None]
        new = np.sum((pr - cen[2 * gr]) ** 2, axis=1) <= np.sum((pr - cen[2 * gr + 1]) ** 2, axis=1)
        n_left = _wsum(gr, new, n_groups)
        bad = (n_left < 1) | (n_left > n - 1)  # a side would be empty: keep the previous split
        new = np.where(bad[gr], lr, new)
        changed = new != lr
        left[ref] = new
        moved = _wsum(gr, changed, n_groups) > 0
        ref = ref[moved[gr]]
    return left


@dataclass(frozen=True, slots=True)
class _Template:
    """The balanced binary tree over ``n`` sorted points (median splits): internal node ``t`` spans
    ranks ``[lo[t], hi[t])``; a child ``c >= 0`` is internal node ``c``, ``c < 0`` the point of rank
    ``-c - 1``. Node 0 is the root."""

    lo: IntArray
    hi: IntArray
    left: IntArray
    right: IntArray


def _template(n: int) -> _Template:
    spans = [(0, n)]
    kids: list[list[int]] = []
    t = 0
    while t < len(spans):
        lo, hi = spans[t]
        mid = lo + (hi - lo) // 2
        pair = []
        for a, b in ((lo, mid), (mid, hi)):
            if b - a == 1:
                pair.append(-a - 1)
            else:
                pair.append(len(spans))
                spans.append((a, b))
        kids.append(pair)
        t += 1
    arr = np.array(spans, dtype=np.int64)
    k = np.array(kids, dtype=np.int64)
    return _Template(arr[:, 0], arr[:, 1], k[:, 0], k[:, 1])


_TEMPLATES = {n: _template(n) for n in range(2, SMALL_GROUP + 1)}


class _TreeBuilder:
    """Accumulates the links and node sums of the tree (node ids: leaves ``0 .. E-1``, then
    internal nodes in creation order)."""

    def __init__(self, leaves: LeafEdges, next_id: int) -> None:
        self.leaves = leaves
        self.next_id = next_id
        self.links: list[tuple[IntArray, IntArray, IntArray]] = []  # (parent, left, right)
        self.sums: list[FloatArray] = []  # (node, count, sum from, sum to, sum cost)

    def record(self, node: IntArray, cnt: FloatArray, ff: FloatArray, tf: FloatArray, cs: FloatArray) -> None:
        self.sums.append(np.stack((node.astype(np.float64), cnt, ff, tf, cs), axis=1))

    def finish_small(self, gid: IntArray, members: IntArray) -> None:
        """Complete the subtrees of groups ``gid (m,)`` whose points ``members (m, n)`` (leaf ids)
        are sorted along the group's major axis, with the median-split template of size ``n``; the
        groups' own sums are already recorded."""
        m, n = members.shape
        tpl = _TEMPLATES[n]
        ids = np.empty((m, n - 1), dtype=np.int64)
        ids[:, 0] = gid
        ids[:, 1:] = self.next_id + np.arange(m * (n - 2), dtype=np.int64).reshape(m, n - 2)
        self.next_id += m * (n - 2)
        lv = self.leaves
        cums = [
            np.concatenate((np.zeros((m, 1)), np.cumsum(a[members].astype(np.float64), axis=1)), axis=1)
            for a in (lv.from_frame, lv.to_frame, lv.cost)
        ]
        for t in range(n - 1):
            lc, rc = int(tpl.left[t]), int(tpl.right[t])
            left = ids[:, lc] if lc >= 0 else members[:, -lc - 1]
            right = ids[:, rc] if rc >= 0 else members[:, -rc - 1]
            self.links.append((ids[:, t], left, right))
            if t:
                lo, hi = int(tpl.lo[t]), int(tpl.hi[t])
                self.record(ids[:, t], np.full(m, float(hi - lo)), *(c[:, hi] - c[:, lo] for c in cums))

    def tree(self) -> EdgeTree:
        lv, e, total = self.leaves, self.leaves.size, self.next_id
        parent = np.full(total, -1, dtype=np.int64)
        left = np.full(total, -1, dtype=np.int64)
        right = np.full(total, -1, dtype=np.int64)
        for par, lc, rc in self.links:
            left[par], right[par] = lc, rc
            parent[lc], parent[rc] = par, par
        fc = np.empty(total, dtype=np.int64)
        tc = np.empty(total, dtype=np.int64)
        ff = np.empty(total, dtype=np.int64)
        tf = np.empty(total, dtype=np.int64)
        cost = np.empty(total, dtype=np.float64)
        fc[:e], tc[:e], ff[:e], tf[:e], cost[:e] = (
            lv.from_clip,
            lv.to_clip,
            lv.from_frame,
            lv.to_frame,
            lv.cost,
        )
        for s in self.sums:
            ids = s[:, 0].astype(np.int64)
            ff[ids] = round_frames(s[:, 2] / s[:, 1])
            tf[ids] = round_frames(s[:, 3] / s[:, 1])
            cost[ids] = s[:, 4] / s[:, 1]
            rep = _representative_leaf(left, e, ids)
            fc[ids], tc[ids] = lv.from_clip[rep], lv.to_clip[rep]
        self.sums.clear()
        return EdgeTree(fc, ff, tc, tf, cost, parent, left, right)


def build_hierarchy(leaves: LeafEdges) -> EdgeTree:
    """The edge tree of ``leaves``: rows ``0 .. E-1`` are the leaves (in the given order), internal
    nodes follow; roots (``parent == -1``) are the top-level clusters of each clip pair (a single
    edge cluster is its own root). Deterministic (no random state).

    Examples
    --------
    >>> e = LeafEdges(np.zeros(3, np.int64), np.array([10, 11, 40]), np.ones(3, np.int64),
    ...               np.array([5, 6, 70]), np.array([0.2, 0.4, 0.3]))
    >>> tree = build_hierarchy(e)
    >>> int(tree.size), tree.roots.tolist(), tree.left.tolist(), tree.right.tolist()
    (4, [2, 3], [-1, -1, -1, 0], [-1, -1, -1, 1])
    >>> tree.from_frame.tolist(), tree.to_frame.tolist(), round(float(tree.cost[3]), 2)
    ([10, 11, 40, 11], [5, 6, 70, 6], 0.3)
    """
    e = leaves.size
    pts = np.stack((leaves.from_frame, leaves.to_frame), axis=1).astype(np.float64)
    forward = (leaves.from_clip == leaves.to_clip) & (leaves.to_frame > leaves.from_frame)
    n_clips = int(max(leaves.from_clip.max(initial=0), leaves.to_clip.max(initial=0))) + 1
    key = (leaves.from_clip * n_clips + leaves.to_clip) * 2 + forward
    _, pair = np.unique(key, return_inverse=True)
    pair = pair.reshape(-1).astype(np.int64)
    cluster, n_clusters = _kmeans_by_group(pair, pts, int(pair.max(initial=-1)) + 1)

    size = np.bincount(cluster, minlength=n_clusters)
    active = np.flatnonzero(size[cluster] >= 2)  # singleton clusters: the leaf is its own root
    g, n_groups = _compact(cluster[active], n_clusters)
    build = _TreeBuilder(leaves, e + n_groups)
    gid = e + np.arange(n_groups, dtype=np.int64)  # node id of each group
    depth = 0
    while active.size:
        p = pts[active]
        n, _, rank = _major_projection(g, p, n_groups)
        build.record(
            gid,
            n,
            _wsum(g, leaves.from_frame[active], n_groups),
            _wsum(g, leaves.to_frame[active], n_groups),
            _wsum(g, leaves.cost[active], n_groups),
        )
        small = n <= SMALL_GROUP
        for k in range(2, SMALL_GROUP + 1):
            groups = np.flatnonzero(n == k)
            if groups.size:
                where = np.full(n_groups, -1, dtype=np.int64)
                where[groups] = np.arange(groups.size)
                sel = np.flatnonzero(where[g] >= 0)
                members = np.empty((groups.size, k), dtype=np.int64)
                members[where[g[sel]], rank[sel]] = active[sel]
                build.finish_small(gid[groups], members)
        big = np.flatnonzero(~small[g])
        if big.size == 0:
            break
        active, p, rank = active[big], p[big], rank[big]
        g, n_groups_big = _compact(g[big], n_groups)
        gid = gid[~small]
        n = n[~small]
        go_left = _split_in_two(g, p, n, rank, n_groups_big, kmeans=depth < MAX_KMEANS_DEPTH)
        ck = 2 * g + (~go_left)
        csize = np.bincount(ck, minlength=2 * n_groups_big)
        multi = csize >= 2
        new_index = np.cumsum(multi) - 1
        child = np.where(multi, build.next_id + new_index, -1)
        lone = ~multi[ck]
        child[ck[lone]] = active[lone]  # a singleton child is the leaf itself
        build.links.append((gid, child[0::2], child[1::2]))
        build.next_id += int(multi.sum())
        keep = multi[ck]
        active = active[keep]
        g = new_index[ck[keep]]
        gid = child[multi]
        n_groups = gid.size
        depth += 1
    return build.tree()


def _representative_leaf(left: IntArray, n_leaves: int, nodes: IntArray) -> IntArray:
    """For each internal node, one leaf below it (following left children)."""
    cur = nodes.copy()
    while True:
        inner = np.flatnonzero(cur >= n_leaves)
        if inner.size == 0:
            return cur
        cur[inner] = left[cur[inner]]
