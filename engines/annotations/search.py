"""Coarse-to-fine anytime search (Arikan, Forsyth & O'Brien 2003, Secs. 3.2-3.4 and 4).

The objective over the output's source frames ``sigma (n,)`` is

    alpha * sum_i D(i, A(sigma_i)) + (1 - alpha) * sum_i C(sigma_i, sigma_i+1) [+ end cost]

with ``D(i, A) = -sum_j Q(i)[j] A[j]`` (timeline ``Q`` in {-1, 0, 1}, database labels ``A`` in
{-1, 1}) and ``C(f, g) = ||F(f + 1) - F(g)||`` on the PCA features (zero when ``g`` follows ``f``
in its clip).

One deviation, on by default (``request.confidence``): for frames the SVMs labelled, ``A`` is the
smoothed decision value clipped to [-1, 1] instead of its sign (user-given labels stay +-1), so
the search prefers frames whose labels are certain. With clips ranked only by sign, a long
mislabelled clip beats several short correctly labelled ones (one cut fewer); on Bandai-Namco
(walk / wave-both-hands / raise-up-both-hands, 3 labelled clips each) this took a
raise-up-then-walk timeline from 64.6% to 100% of frames from truly matching clips.

One *pass*:

1. **32-frame level.** ``ceil(n / 32)`` time slots; each slot's active set is one random block
   from every k-means cluster of 32-frame blocks (a stratified sample); exact DP over the slots
   (:func:`engines.annotations.dp.solve_chain`).
2. **16, then 8.** Each block of the previous solution splits into child blocks; a child slot's
   active set is the child block itself, its shifts by +-1 and +-2 frames, and
   ``active_per_cluster`` random members of the child block's cluster at that level (the finer
   clusterings hold about 100 blocks each). The previous solution is in the active sets, so a
   level never makes the solution worse.
3. **Boundary refinement** (Sec. 4): every cut moves by up to ``refine_frames`` frames (the exit
   frame of the earlier piece and the entry frame of the later one move together, so the length
   stays exact), keeping the best value of the full objective (the paper's descent on the feature
   gap, done exhaustively over the small window).
4. **Assembly**: pieces are placed on the floor so each continues where the previous one would
   have gone (the cached per-frame root transforms), cuts are smoothed
   (:func:`motion.smoothing.smooth_cuts`) and foot skate removed (:mod:`motion.footskate`, when
   installed).

Passes repeat with new random active sets; every better motion is emitted (anytime, seeded by
``request.seed``).

Constraints. *Frame constraints* reduce the active set of the slot containing the frame to the one
block that puts the database frame at that time (Sec. 3.3); refinement never moves a constrained
frame; a constraint the blocks cannot honour (two in one block, a clip shorter than a block) is
forced at the end by playing a few frames around it from its clip (:func:`force_constraints`).
*End position / heading* (Sec. 3.4): each level keeps a pool of its ``pool_size`` best motions;
a new motion is also tried with a single cut (at the level's block boundaries) to or from every
pooled motion, each in O(1) from the cached per-frame placements, and the best replaces it.
*Length* is exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from motion.rotations import wrap_angle
from schemas.annotations import AnnotationRequest

from ..base import Arrays, EngineError
from ..library import MotionLibrary
from .blocks import next_features
from .database import AnnotatedDatabase
from .dp import solve_chain
from .labels import LabelTable, clip_refs, clip_starts

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

TRANSITION_MARGIN = 15
"""Frames on either side of a change of the timeline excluded from ``label_match_steady``."""

SHIFTS = (-2, -1, 1, 2)
"""Shifts of the parent's block added to every finer active set."""


def rot2(theta: FloatArray | float, v: FloatArray) -> FloatArray:
    """Rotate floor vectors ``v (..., 2)`` ``[x, z]`` by ``theta (...)`` radians about +Y (heading
    increases by ``theta``; :func:`motion.align.apply_rigid_2d`'s convention)."""
    th = np.asarray(theta, dtype=np.float64)
    c, s = np.cos(th), np.sin(th)
    return np.stack((c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1]), axis=-1)


@dataclass(slots=True)
class Clustering:
    """One level's block clustering in CSR form."""

    size: int
    cluster_of: npt.NDArray[np.int32]  # (N,) cluster of the block starting at each frame, -1 none
    members: IntArray  # (B,) block starts sorted by cluster
    offsets: IntArray  # (K + 1,)

    @classmethod
    def of(cls, size: int, cluster_of: npt.NDArray[np.int32]) -> Clustering:
        valid = np.flatnonzero(cluster_of >= 0)
        order = np.argsort(cluster_of[valid], kind="stable")
        members = valid[order].astype(np.intp)
        k = int(cluster_of.max()) + 1 if valid.size else 0
        counts = np.bincount(cluster_of[valid], minlength=k)
        offsets = np.concatenate(([0], np.cumsum(counts))).astype(np.intp)
        return cls(size, cluster_of, members, offsets)

    @property
    def clusters(self) -> int:
        return self.offsets.size - 1

    def sample(self, clusters: IntArray, u: FloatArray) -> IntArray:
        """Random members: ``clusters (...)`` with uniform numbers ``u (..., m)`` -> ``(..., m)``."""
        lo = self.offsets[clusters][..., None]
        n = (self.offsets[clusters + 1] - self.offsets[clusters])[..., None]
        return np.asarray(self.members[lo + np.minimum((u * n).astype(np.intp), n - 1)], dtype=np.intp)


@dataclass(slots=True)
class Database(LabelTable):
    """The loaded annotated database (see :mod:`engines.annotations.build` for the arrays): the
    label table plus what the search needs."""

    clip_of: IntArray  # (N,)
    confidence: npt.NDArray[np.float32]  # (N, L) +-1 where user-given, else decision clipped to [-1, 1]
    features: npt.NDArray[np.float32]  # (N, d)
    fnext: npt.NDArray[np.float32]  # (N, d)
    xz: FloatArray  # (N, 2)
    yaw: FloatArray  # (N,)
    xz_next: FloatArray  # (N, 2) body position one frame later (extrapolated at clip ends)
    yaw_next: FloatArray  # (N,)
    levels: list[Clustering]

    @classmethod
    def from_arrays(cls, library: MotionLibrary, arrays: Arrays) -> Database:
        counts = np.array([m.num_frames for m in library.motions], dtype=np.intp)
        starts = clip_starts(counts)
        clip_of = np.repeat(np.arange(counts.size, dtype=np.intp), counts)
        stored = AnnotatedDatabase.from_arrays(arrays)
        feats = np.asarray(stored.features, dtype=np.float32)
        xz = np.asarray(stored.ground_xz, dtype=np.float64)
        yaw = np.asarray(stored.ground_yaw, dtype=np.float64)
        xz_next = np.empty_like(xz)
        yaw_next = np.empty_like(yaw)
        xz_next[:-1], yaw_next[:-1] = xz[1:], yaw[1:]
        last = starts + counts - 1
        prev = np.maximum(last - 1, starts)
        xz_next[last] = 2 * xz[last] - xz[prev]
        yaw_next[last] = 2 * yaw[last] - yaw[prev]
        labels = np.asarray(stored.labels, dtype=np.int8)
        known = np.asarray(stored.known, dtype=bool)
        decision = np.asarray(stored.decision, dtype=np.float32)
        levels = [Clustering.of(s, np.asarray(cl, dtype=np.int32)) for s, cl in stored.clusters.items()]
        return cls(
            names=library.names,
            refs=clip_refs(arrays, library.names),
            counts=counts,
            clip_start=starts,
            clip_of=clip_of,
            vocab=[str(v) for v in stored.vocab.reshape(-1)],
            labels=labels,
            confidence=np.where(known, labels, np.clip(decision, -1.0, 1.0)).astype(np.float32),
            features=feats,
            fnext=next_features(feats, counts.tolist()),
            xz=xz,
            yaw=yaw,
            xz_next=xz_next,
            yaw_next=yaw_next,
            levels=levels,
        )

    @property
    def frames(self) -> int:
        return int(self.clip_of.size)


@dataclass(slots=True)
class Problem:
    """A request compiled against a database."""

    n: int
    alpha: float
    q: FloatArray  # (n, T) timeline values of the requested labels
    cols: IntArray  # (T,) their columns in the database vocabulary
    constraints: list[tuple[int, int]]  # (output frame, database frame)
    start_xz: FloatArray
    start_yaw: float
    end_xz: FloatArray | None
    end_yaw: float | None
    end_weight: float
    fixed: npt.NDArray[np.bool_]  # (n,) output frames refinement must not change
    lab: FloatArray  # (N, T) database labels (or confidences) of the timeline's labels
    cum: FloatArray  # (N + 1, T) their cumulative sums over database frames
    changes: IntArray  # (n,) number of timeline changes up to each output frame

    @classmethod
    def compile(cls, request: AnnotationRequest, db: Database) -> Problem:
        n = int(request.frames)
        names = list(dict.fromkeys(e.label for e in request.timeline))
        unknown = [x for x in names if x not in db.vocab]
        if unknown:
            raise EngineError(
                f"label(s) {', '.join(map(repr, unknown))} are not in the database's vocabulary "
                f"({', '.join(db.vocab) or 'no labels'})"
            )
        q = np.zeros((n, len(names)))
        for e in request.timeline:  # later entries paint over earlier ones
            q[e.start : e.end, names.index(e.label)] = e.value
        cols = np.array([db.vocab.index(x) for x in names], dtype=np.intp)
        constraints = [
            (int(c.frame), db.frame_of(c.clip, int(c.clip_frame))) for c in request.frame_constraints
        ]
        fixed = np.zeros(n, dtype=bool)
        for t, _ in constraints:
            fixed[t] = True
        end = request.end
        source = db.confidence if request.confidence else db.labels
        lab = source[:, cols].astype(np.float64)
        change = np.zeros(n, dtype=np.intp)
        if names:
            change[1:] = np.any(q[1:] != q[:-1], axis=1)
        return cls(
            n=n,
            alpha=float(request.alpha),
            q=q,
            cols=cols,
            constraints=constraints,
            start_xz=np.asarray(request.start.position, dtype=np.float64),
            start_yaw=float(np.radians(request.start.heading_deg)),
            end_xz=None if end is None else np.asarray(end.position, dtype=np.float64),
            end_yaw=None if end is None or end.heading_deg is None else float(np.radians(end.heading_deg)),
            end_weight=0.0 if end is None else float(end.weight),
            fixed=fixed,
            lab=lab,
            cum=np.concatenate((np.zeros((1, cols.size)), np.cumsum(lab, axis=0))),
            changes=np.cumsum(change),
        )

    @property
    def has_end(self) -> bool:
        return self.end_xz is not None

    def end_cost(self, xz: FloatArray, yaw: FloatArray | np.float64) -> FloatArray:
        """``weight * 10 * (distance / 0.3 m + heading error / 10 deg)`` for end poses ``(..., 2)``,
        ``(...)``."""
        if self.end_xz is None:
            return np.zeros(np.shape(yaw))
        cost = np.linalg.norm(xz - self.end_xz, axis=-1) / 0.3
        if self.end_yaw is not None:
            cost = cost + np.degrees(np.abs(wrap_angle(yaw - self.end_yaw))) / 10.0
        return np.asarray(self.end_weight * 10.0 * cost)


# -- the objective ---------------------------------------------------------------------------------


def frame_costs(db: Database, pb: Problem, sigma: IntArray) -> tuple[FloatArray, FloatArray]:
    """Per output frame ``D (n,)`` and per transition ``C (n - 1,)`` (unweighted)."""
    d = -np.einsum("nt,nt->n", pb.q, pb.lab[sigma])
    diff = db.fnext[sigma[:-1]].astype(np.float64) - db.features[sigma[1:]]
    c = np.sqrt(np.einsum("nd,nd->n", diff, diff))
    return d, c


def placements(db: Database, pb: Problem, sigma: IntArray) -> tuple[FloatArray, FloatArray]:
    """Per output frame the floor transform (``theta (n,)`` rad, ``shift (n, 2)`` m) that moves its
    source frame so each piece continues where the previous one would have gone."""
    n = sigma.size
    cut = np.ones(n, dtype=bool)
    cut[1:] = (sigma[1:] != sigma[:-1] + 1) | (db.clip_of[sigma[1:]] != db.clip_of[sigma[:-1]])
    heads = np.flatnonzero(cut)
    prev_end = sigma[heads[1:] - 1]
    first = sigma[heads]
    dtheta = np.concatenate(([pb.start_yaw - db.yaw[first[0]]], db.yaw_next[prev_end] - db.yaw[first[1:]]))
    theta_p = np.cumsum(dtheta)
    # shift_p = shift_{p-1} + R(theta_{p-1}) xz_next(prev end) - R(theta_p) xz(first_p)
    steps = np.zeros((heads.size, 2))
    steps[0] = pb.start_xz - rot2(theta_p[0], db.xz[first[0]])
    if heads.size > 1:
        steps[1:] = rot2(theta_p[:-1], db.xz_next[prev_end]) - rot2(theta_p[1:], db.xz[first[1:]])
    shift_p = np.cumsum(steps, axis=0)
    piece = np.cumsum(cut) - 1
    return theta_p[piece], shift_p[piece]


def end_pose(db: Database, sigma: IntArray, theta: FloatArray, shift: FloatArray) -> tuple[FloatArray, float]:
    """World body position ``(2,)`` m and heading (rad) at the last output frame."""
    last = int(sigma[-1])
    return rot2(theta[-1], db.xz[last]) + shift[-1], float(db.yaw[last] + theta[-1])


@dataclass(slots=True)
class Candidate:
    """A complete frame sequence with its cached objective parts (the pool of Sec. 3.4)."""

    sigma: IntArray
    d: FloatArray
    c: FloatArray
    theta: FloatArray
    shift: FloatArray
    end_xz: FloatArray
    end_yaw: float
    score: float

    @classmethod
    def of(cls, db: Database, pb: Problem, sigma: IntArray) -> Candidate:
        d, c = frame_costs(db, pb, sigma)
        theta, shift = placements(db, pb, sigma)
        exz, eyaw = end_pose(db, sigma, theta, shift)
        score = pb.alpha * d.sum() + (1 - pb.alpha) * c.sum() + float(pb.end_cost(exz, np.float64(eyaw)))
        return cls(sigma, d, c, theta, shift, exz, eyaw, float(score))


def spliced(db: Database, pb: Problem, x: Candidate, y: Candidate, size: int) -> tuple[float, int]:
    """The best single cut ``x[:k] + y[k:]`` at multiples ``k`` of ``size``: its score and ``k``
    (``(inf, 0)`` when there is no cut position). O(1) per cut from the cached placements."""
    n = x.sigma.size
    ks = np.arange(size, n, size)
    if ks.size == 0:
        return float("inf"), 0
    dx = np.concatenate(([0.0], np.cumsum(x.d)))
    dy = np.concatenate(([0.0], np.cumsum(y.d)))
    cx = np.concatenate(([0.0], np.cumsum(x.c)))
    cy = np.concatenate(([0.0], np.cumsum(y.c)))
    a, b = x.sigma[ks - 1], y.sigma[ks]
    gap = db.fnext[a].astype(np.float64) - db.features[b]
    c_cut = np.sqrt(np.einsum("kd,kd->k", gap, gap))
    d_tot = dx[ks] + dy[n] - dy[ks]
    c_tot = cx[ks - 1] + c_cut + cy[n - 1] - cy[ks]
    # placement of y[k] after x[k-1], then y's tail moved rigidly by T_new(k) o T_y(k)^-1
    th_x = x.theta[ks - 1]
    cont = db.clip_of[b] == db.clip_of[a]
    cont &= b == a + 1
    th_new = np.where(cont, th_x, th_x + db.yaw_next[a] - db.yaw[b])
    sh_new = rot2(th_x, db.xz_next[a]) + x.shift[ks - 1] - rot2(th_new, db.xz[b])
    local = rot2(-y.theta[ks], y.end_xz[None, :] - y.shift[ks])
    end_xz = rot2(th_new, local) + sh_new
    end_yaw = y.end_yaw + th_new - y.theta[ks]
    total = pb.alpha * d_tot + (1 - pb.alpha) * c_tot + pb.end_cost(end_xz, end_yaw)
    i = int(np.argmin(total))
    return float(total[i]), int(ks[i])


# -- levels ----------------------------------------------------------------------------------------


def blocks_to_sigma(starts: IntArray, size: int, n: int) -> IntArray:
    """``(n,)`` source frames of blocks ``starts (K,)`` of ``size`` frames laid end to end."""
    t = np.arange(n)
    return np.asarray(starts[t // size] + t % size, dtype=np.intp)


def constrained_start(
    db: Database, size: int, slot: int, t: int, g: int, length: int | None = None
) -> int | None:
    """Start of the block of slot ``slot`` (``size`` frames, of which the slot plays ``length``,
    default all) that plays database frame ``g`` at output ``t``, clamped into ``g``'s clip;
    ``None`` if the clip is shorter than that."""
    c = int(db.clip_of[g])
    length = size if length is None else length
    lo, hi = int(db.clip_start[c]), int(db.clip_start[c] + db.counts[c] - length)
    if hi < lo:
        return None
    return int(np.clip(g - (t - slot * size), lo, hi))


def slot_unary(db: Database, pb: Problem, active: IntArray, size: int) -> FloatArray:
    """``(K, M)`` ``alpha * sum D`` of each candidate block over its slot's frames.

    Slots where the timeline is constant use the cumulative label sums (O(1) per block); the
    others sum frame by frame."""
    k_slots, m = active.shape
    out = np.zeros((k_slots, m))
    if pb.cols.size == 0:
        return out
    t0 = np.arange(k_slots) * size
    lens = np.minimum(size, pb.n - t0)
    sums = pb.cum[active + lens[:, None]] - pb.cum[active]  # (K, M, T)
    out = -np.einsum("kmt,kt->km", sums, pb.q[t0])
    changes = pb.changes[t0 + lens - 1] - pb.changes[t0]
    for k in np.flatnonzero(changes).tolist():
        frames = active[k][:, None] + np.arange(int(lens[k]))[None, :]
        out[k] = -np.einsum("mbt,bt->m", pb.lab[frames], pb.q[t0[k] : t0[k] + lens[k]])
    return np.asarray(pb.alpha * out)


PAIR_CHUNK = 128
"""Slots whose transition matrices are computed together (bounds memory for long outputs)."""


def solve_level(db: Database, pb: Problem, active: IntArray, size: int) -> tuple[IntArray, float]:
    """The DP optimum over active sets ``(K, M)`` of blocks of ``size``: block starts ``(K,)`` and
    the objective of their frame sequence (without the end cost).

    Transition costs of a chunk of slots are computed at once (batched ``|e|^2 + |h|^2 - 2 e.h``,
    float64); a block that continues its predecessor in the same clip costs exactly 0."""
    unary = slot_unary(db, pb, active, size)
    w = 1.0 - pb.alpha
    cache: dict[int, FloatArray] = {}

    def pair(k: int) -> FloatArray:
        if k not in cache:
            cache.clear()
            hi = min(k + PAIR_CHUNK, active.shape[0])
            prev, cur = active[k - 1 : hi - 1], active[k:hi]
            e = db.fnext[prev + size - 1].astype(np.float64)  # (C, M, d)
            h = db.features[cur].astype(np.float64)
            d2 = np.einsum("cmd,cmd->cm", e, e)[:, :, None] + np.einsum("cmd,cmd->cm", h, h)[:, None, :]
            d2 -= 2.0 * np.matmul(e, h.transpose(0, 2, 1))
            dist = np.sqrt(np.maximum(d2, 0.0))
            natural = (cur[:, None, :] == prev[:, :, None] + size) & (
                db.clip_of[cur][:, None, :] == db.clip_of[prev][:, :, None]
            )
            dist[natural] = 0.0
            dist *= w
            for i in range(hi - k):
                cache[k + i] = dist[i]
        return cache[k]

    choice, cost = solve_chain(unary, pair)
    return active[np.arange(active.shape[0]), choice], cost


def apply_constraints(db: Database, pb: Problem, active: IntArray, size: int) -> IntArray:
    """Active sets with each frame-constrained slot reduced to its single block."""
    for t, g in pb.constraints:
        slot = t // size
        s = constrained_start(db, size, slot, t, g, min(size, pb.n - slot * size))
        if s is not None:
            active[slot] = s
    return active


def top_active(db: Database, pb: Problem, rng: np.random.Generator) -> IntArray:
    """``(K, clusters)`` one random block per cluster per slot of the top level."""
    lv = db.levels[0]
    k_slots = -(-pb.n // lv.size)
    clusters = np.arange(lv.clusters, dtype=np.intp)
    u = rng.random((k_slots, lv.clusters, 1))
    active = lv.sample(np.broadcast_to(clusters, (k_slots, lv.clusters)), u)[..., 0]
    return apply_constraints(db, pb, np.ascontiguousarray(active), lv.size)


def child_active(
    db: Database,
    pb: Problem,
    parent: IntArray,
    parent_size: int,
    level: Clustering,
    per_cluster: int,
    rng: np.random.Generator,
) -> IntArray:
    """``(K, 1 + shifts + per_cluster)`` active sets near the parent solution: each child block, its
    small shifts, and random members of its cluster."""
    size = level.size
    r = parent_size // size
    k_slots = -(-pb.n // size)
    j = np.arange(k_slots)
    child = parent[j // r] + (j % r) * size
    shifted = child[:, None] + np.array(SHIFTS)[None, :]
    inside = (shifted >= 0) & (shifted < db.frames)
    ok = inside & (level.cluster_of[np.clip(shifted, 0, db.frames - 1)] >= 0)
    shifted = np.where(ok, shifted, child[:, None])
    cl = level.cluster_of[child].astype(np.intp)
    # a constrained last slot may hold a block shorter than ``size``: it has no cluster
    sampled = level.sample(np.maximum(cl, 0), rng.random((k_slots, per_cluster)))
    sampled = np.where(cl[:, None] >= 0, sampled, child[:, None])
    active = np.concatenate((child[:, None], shifted, sampled), axis=1)
    return apply_constraints(db, pb, np.ascontiguousarray(active), size)


# -- boundary refinement -----------------------------------------------------------------------------


def cuts_of(db: Database, sigma: IntArray) -> IntArray:
    """Output frames where a new piece starts (``sigma`` jumps or changes clip)."""
    jump = (sigma[1:] != sigma[:-1] + 1) | (db.clip_of[sigma[1:]] != db.clip_of[sigma[:-1]])
    return np.flatnonzero(jump) + 1


def refine_boundaries(db: Database, pb: Problem, sigma: IntArray, radius: int) -> IntArray:
    """Move every cut by up to ``radius`` frames where that lowers the objective (Sec. 4).

    Moving the cut at output frame ``c`` by ``delta`` plays ``delta`` more (or fewer) frames of the
    earlier piece and enters the later piece ``delta`` frames later (earlier): the length stays
    exact and only frames between the old and the new cut change, so cuts are refined one after
    the other, left to right, each within its neighbours. Frame-constrained output frames never
    change."""
    if radius < 1:
        return sigma
    sigma = sigma.copy()
    n = sigma.size
    deltas = np.arange(-radius, radius + 1)
    cuts = cuts_of(db, sigma)
    prev = 0
    for i, c in enumerate(cuts.tolist()):
        nxt = int(cuts[i + 1]) if i + 1 < cuts.size else n
        a_end, b_start = int(sigma[c - 1]), int(sigma[c])
        ca, cb = int(db.clip_of[a_end]), int(db.clip_of[b_start])
        a_last = int(db.clip_start[ca] + db.counts[ca] - 1)
        b_first = int(db.clip_start[cb])
        ok = (deltas > prev - c) & (deltas < nxt - c)
        ok &= (a_end + np.maximum(deltas, 0) <= a_last) & (b_start + np.minimum(deltas, 0) >= b_first)
        lo, hi = max(c - radius - 1, 0), min(c + radius + 1, n)
        t = np.arange(lo, hi)[None, :]
        dl = deltas[:, None]
        cand = np.broadcast_to(sigma[lo:hi], (deltas.size, hi - lo)).copy()
        grow = (dl > 0) & (t >= c) & (t < c + dl)
        shrink = (dl < 0) & (t >= c + dl) & (t < c)
        cand = np.where(grow, a_end + 1 + (t - c), cand)
        cand = np.where(shrink, b_start + (t - c), cand)
        cand = np.clip(cand, 0, db.frames - 1)
        ok &= ~np.any((cand != sigma[lo:hi]) & pb.fixed[lo:hi], axis=1)
        lab = pb.lab[cand]  # (D, W, T)
        dcost = -np.einsum("kwt,wt->k", lab, pb.q[lo:hi])
        gap = db.fnext[cand[:, :-1]].astype(np.float64) - db.features[cand[:, 1:]]
        ccost = np.sqrt(np.einsum("kwd,kwd->kw", gap, gap)).sum(axis=1)
        total = pb.alpha * dcost + (1 - pb.alpha) * ccost
        total[~ok] = np.inf
        best = int(np.argmin(total))
        if np.isfinite(total[best]) and total[best] < total[radius] - 1e-9:
            sigma[lo:hi] = cand[best]
            prev = c + int(deltas[best])
        else:
            prev = c
    return sigma


FORCE_RADIUS = 4
"""Frames on each side of an unmet frame constraint played from the constrained clip."""


def force_constraints(db: Database, pb: Problem, sigma: IntArray) -> IntArray:
    """``sigma`` with every frame constraint met: where the blocks could not honour one (two
    constraints in one block, a clip shorter than a block), the constrained frame and up to
    :data:`FORCE_RADIUS` frames either side (within its clip, stopping half-way to the next
    constrained frame) are played from the constrained clip."""
    if not pb.constraints:
        return sigma
    sigma = sigma.copy()
    times = sorted(t for t, _ in pb.constraints)
    for t, g in pb.constraints:
        if sigma[t] == g:
            continue
        i = times.index(t)
        lo = t - FORCE_RADIUS if i == 0 else max(t - FORCE_RADIUS, (times[i - 1] + t) // 2 + 1)
        hi = (
            t + FORCE_RADIUS
            if i == len(times) - 1
            else min(t + FORCE_RADIUS, (t + times[i + 1] + 1) // 2 - 1)
        )
        c = int(db.clip_of[g])
        first, last = int(db.clip_start[c]), int(db.clip_start[c] + db.counts[c] - 1)
        lo = max(lo, 0, t - (g - first))
        hi = min(hi, pb.n - 1, t + (last - g))
        sigma[lo : hi + 1] = g + np.arange(lo - t, hi - t + 1)
    return sigma
