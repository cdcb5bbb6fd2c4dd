"""The segment dynamic programme of Hsu, Gentry & Popović 2004 (Sec. 4), vectorized.

Notation (the paper's): the input control ``x`` has ``T`` frames at the solve rate ``r``; a *cell* is a
legal (instance ``s``, duration ``d``) pair, ``d`` frames being ``s``'s control segment uniformly
stretched within the stretch bound. A cell *ending at* ``t`` covers input frames ``[t - d, t)``.

* **Interpretation distance** (Eq. 1-2) ``D[c, t] = ||x_{d,t} - M a_s^d||^2`` for every cell and
  every end time at once: the closed-form rotation about +Y and floor translation comes from window
  sums (cumulative sums) and cross-correlations (one matrix product per duration). Units: mean over
  points, integrated over time (m²·s), so scores do not depend on the rate.
* **Continuity** (Eq. 4) between the aligned tail of the previous target segment and the aligned head
  of the next: ``C = mean_points ||M_r w(b_r) - M_s a(b_s)||^2`` (m²); heads and tails are the target
  points at the same source instant (a segment's end point is the next source frame), so a seamless
  source continuation scores 0. For all predecessor/successor pairs at a boundary it is one matrix
  product ``|y|^2 + |h|^2 - 2 Y H^T``.
* **DP** (Eq. 6-8): forward over boundaries ``t``; at each, all predecessors ending at ``t`` and all
  successors starting at ``t`` at once; back pointers; best cell at ``T``. **Beam** (Sec. 4.4): keep
  predecessors within ``w`` of the best at ``t``. **Exact** search with pruning that cannot change the
  optimum (branch and bound): a cell is dropped when its score plus an admissible bound of the cost
  still to come (the best tiling by ``D`` alone, continuity >= 0) exceeds a known solution's score.
* **Hard constraints**: "instance ``s`` at time ``t``" makes every cell of another instance covering
  ``t`` illegal (infinite ``D``).
* **Re-timing** (Sec. 4.4 "Downsampling"): the coarse solution's instances are kept and only the
  boundaries move, within a window around the upsampled coarse ones, by a constrained DP at the full
  rate over (segment, duration, end) states.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from motion.align import kabsch, rotation_from_covariance

from .kernels import cost_to_go as kernel_cost_to_go
from .kernels import duration_operands, forward, residual_block, retime_chain, sample_frames, state_alignments
from .points import sample_cloud
from .tier import compiled_ready

Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


class Infeasible(ValueError):
    """No tiling of the input satisfies the durations and constraints."""


# ------------------------------------------------------------------------------ alignment helpers


def align_points(points: Array, cos: Array, sin: Array, tx: Array, tz: Array) -> Array:
    """Rotate ``points (N, ..., 3)`` about +Y by per-row ``(cos, sin)`` then translate by ``[tx, tz]``."""
    extra = (1,) * (points.ndim - 2)
    c, s = cos.reshape(-1, *extra), sin.reshape(-1, *extra)
    out = points.copy()
    x, z = points[..., 0], points[..., 2]
    out[..., 0] = c * x + s * z + tx.reshape(-1, *extra)
    out[..., 2] = -s * x + c * z + tz.reshape(-1, *extra)
    return out


def paired_alignment(windows: Array, templates: Array) -> tuple[Array, Array, Array, Array, Array]:
    """Closed-form alignment of templates ``(M, N, 3)`` onto windows ``(M, N, 3)`` (row by row).

    Returns the residual sum of squares ``(M,)`` and ``cos, sin, tx, tz`` ``(M,)`` of the transform
    taking the template onto the window."""
    n = windows.shape[1]
    wx, wz, wy = windows[..., 0], windows[..., 2], windows[..., 1]
    ax, az, ay = templates[..., 0], templates[..., 2], templates[..., 1]
    mwx, mwz, max_, maz = wx.mean(1), wz.mean(1), ax.mean(1), az.mean(1)
    cwx, cwz, cax, caz = wx - mwx[:, None], wz - mwz[:, None], ax - max_[:, None], az - maz[:, None]
    c = (cax * cwx + caz * cwz).sum(1)
    s = (caz * cwx - cax * cwz).sum(1)
    r = np.hypot(c, s)
    safe = np.where(r > 0, r, 1.0)
    cos, sin = np.where(r > 0, c / safe, 1.0), np.where(r > 0, s / safe, 0.0)
    res = (cwx**2 + cwz**2).sum(1) + (cax**2 + caz**2).sum(1) - 2 * r + ((wy - ay) ** 2).sum(1)
    tx = mwx - (cos * max_ + sin * maz)
    tz = mwz - (-sin * max_ + cos * maz)
    del n
    return np.maximum(res, 0.0), cos, sin, tx, tz


def paired_procrustes(windows: Array, templates: Array) -> tuple[Array, Array, Array]:
    """Full 3-D rigid alignment (rotation + translation, no scale) of templates ``(M, N, 3)`` onto
    windows ``(M, N, 3)``, row by row (:func:`motion.align.kabsch`). Returns the residual sum of
    squares ``(M,)``, rotations ``(M, 3, 3)`` and translations ``(M, 3)`` (``R a + t`` is the
    template placed on the window)."""
    rot, trans = kabsch(templates, windows)
    placed = np.einsum("mij,mnj->mni", rot, templates) + trans[:, None, :]
    return ((placed - windows) ** 2).sum((1, 2)), rot, trans


def place_points(
    points: Array,
    cos: Array,
    sin: Array,
    tx: Array,
    tz: Array,
    rot: Array | None = None,
    trans: Array | None = None,
) -> Array:
    """Points ``(N, ..., 3)`` moved by per-row transforms: the 3-D ``rot (N, 3, 3)``, ``trans (N, 3)``
    when given, else the floor transform ``cos, sin, tx, tz`` (:func:`align_points`)."""
    if rot is None or trans is None:
        return align_points(points, cos, sin, tx, tz)
    return rigid_points(points, rot, trans)


def rigid_points(points: Array, rot: Array, trans: Array) -> Array:
    """Points ``(N, ..., 3)`` moved by per-row rotations ``rot (N, 3, 3)`` then ``trans (N, 3)``."""
    flat = points.reshape(points.shape[0], -1, 3)
    out = np.einsum("nij,npj->npi", rot, flat) + trans[:, None, :]
    return np.asarray(out.reshape(points.shape))


# ------------------------------------------------------------------------------------- the problem


@dataclass(slots=True)
class Instances:
    """The kept instances as the solver sees them (database rate ``fps``).

    ``start``: ``(N,)`` first frame of each control/target segment in the database's concatenated
    arrays; ``length``: ``(N,)`` frames; ``control``: ``(F, Pc, 3)``; ``tails``/``heads``: ``(N, Q, 3)``
    target points at each segment's end point and start (the same source instant for consecutive
    source segments)."""

    fps: float
    start: IntArray
    length: IntArray
    control: Array
    tails: Array
    heads: Array
    pair_bounds: IntArray | None = None  # (N, 2) first and last frame of each instance's pair

    @property
    def count(self) -> int:
        return int(self.start.shape[0])


def legal_cells(
    lengths_s: Array, rate: float, stretch_s: float | None, stretch_ratio: float | None
) -> tuple[IntArray, IntArray]:
    """All legal (instance, duration) cells: durations ``d`` (frames at ``rate``) with
    ``|d / rate - L| <= stretch_s`` (or ``|d - L rate| <= stretch_ratio L rate``); the nearest
    duration to the unstretched length is always legal. Returns ``(instance (C,), duration (C,))``
    sorted by duration."""
    lo_i, hi_i = _legal_range(lengths_s, rate, stretch_s, stretch_ratio)
    counts = hi_i - lo_i + 1
    inst = np.repeat(np.arange(lengths_s.shape[0]), counts)
    dur = lo_i[inst] + (np.arange(inst.size) - np.repeat(np.cumsum(counts) - counts, counts))
    order = np.argsort(dur, kind="stable")
    return inst[order].astype(np.intp), dur[order].astype(np.intp)


def stretched_templates(inst: Instances, which: IntArray, d: int, rate: float, context: int = 0) -> Array:
    """``(n, d + 2 context, Pc, 3)``: control segments ``which`` uniformly stretched to ``d`` frames at
    ``rate`` (sample ``i`` at source frame ``start + (i - context) length / d``), with ``context``
    frames of the surrounding source control on either side (clamped to the pair)."""
    i = (np.arange(d + 2 * context) - context) / d
    pos = inst.start[which, None] + inst.length[which, None] * i[None, :]
    if context and inst.pair_bounds is not None:
        b = inst.pair_bounds[which]
        pos = np.clip(pos, b[:, :1], b[:, 1:])
    if compiled_ready() and inst.control.ndim == 3 and inst.control.dtype == np.float64:
        return np.asarray(sample_frames(np.ascontiguousarray(inst.control), np.ascontiguousarray(pos)))
    return sample_cloud(inst.control, pos)


def pad_edges(x: Array, context: int) -> Array:
    """``x (T, ...)`` with ``context`` copies of its first and last frames added."""
    if context <= 0:
        return x
    return np.concatenate((np.repeat(x[:1], context, 0), x, np.repeat(x[-1:], context, 0)))


@dataclass(slots=True)
class Interpretation:
    """Per cell and end time ``t`` (stored time-major, ``(T + 1, C)``: a boundary's cells are one
    contiguous row for the DP kernel; :attr:`D`, :attr:`c`, :attr:`s` are the ``(C, T + 1)``
    views; infinite where illegal): the distance ``D`` (m²·s) of the stretched control segment to
    the input window ``[t - d, t)``, and what its optimal alignment (rotation about +Y, floor
    translation) is made of, evaluated on demand by :meth:`alignment` (the solver only needs the
    alignments of the cells it expands).

    ``DT``, ``CT``, ``ST``: ``(T + 1, C)`` the distances and the centred planar cross-correlations
    (the rotation is ``atan2(s, c)``); ``sum_a``: ``(C, 2)`` the stretched template's summed ``x``,
    ``z``; ``n_pts``: ``(C,)`` points per comparison; ``dur``: ``(C,)`` durations; ``context``:
    frames of context on each side; ``cs``: ``(T + 2 context + 1, 2)`` cumulative sums of the padded
    input's ``x``, ``z`` (summed over points)."""

    DT: Array
    CT: Array
    ST: Array
    sum_a: Array
    n_pts: Array
    dur: IntArray
    context: int
    cs: Array
    rot: Array | None = None  # (C, T + 1, 3, 3) rigid (3-D) alignment rotations
    trans: Array | None = None  # (C, T + 1, 3) rigid alignment translations

    @property
    def D(self) -> Array:  # noqa: N802 (the paper's name)
        """``(C, T + 1)`` the distances (a view of :attr:`DT`: writes reach the solver)."""
        return self.DT.T

    @property
    def c(self) -> Array:
        """``(C, T + 1)`` the centred cross-correlations ``ax.wx + az.wz`` (a view)."""
        return self.CT.T

    @property
    def s(self) -> Array:
        """``(C, T + 1)`` the centred cross-correlations ``az.wx - ax.wz`` (a view)."""
        return self.ST.T

    @property
    def rigid(self) -> bool:
        """Whether the alignments are full 3-D rigid transforms (else rotation about +Y + floor)."""
        return self.rot is not None

    def place(self, points: Array, cells: IntArray, ends: IntArray) -> Array:
        """``points (n, ..., 3)`` moved by the alignment of ``cells (n,)`` ending at ``ends (n,)``."""
        if self.rot is not None and self.trans is not None:
            return rigid_points(points, self.rot[cells, ends], self.trans[cells, ends])
        m = self.alignment(cells, ends)
        return align_points(points, m[0], m[1], m[2], m[3])

    def alignment(self, cells: IntArray, ends: IntArray) -> Array:
        """``(4, n)``: ``cos, sin, tx, tz`` of the transform taking the stretched control segment of
        ``cells (n,)`` onto the input window ending at ``ends (n,)`` (``ends >= `` the durations)."""
        c, s = self.CT[ends, cells], self.ST[ends, cells]
        r = np.hypot(c, s)
        pos = r > 0
        inv = np.divide(1.0, r, out=np.zeros_like(r), where=pos)
        out = np.empty((4, cells.shape[0]))
        cth, sth = out[0], out[1]
        np.multiply(c, inv, out=cth)
        cth[~pos] = 1.0
        np.multiply(s, inv, out=sth)
        lo = np.maximum(ends - self.dur[cells], 0)
        inv_n = 1.0 / self.n_pts[cells]
        mw = (self.cs[ends + 2 * self.context] - self.cs[lo]) * inv_n[:, None]
        ma = self.sum_a[cells] * inv_n[:, None]
        out[2] = mw[:, 0] - (cth * ma[:, 0] + sth * ma[:, 1])
        out[3] = mw[:, 1] - (cth * ma[:, 1] - sth * ma[:, 0])
        return out

    @property
    def alignments(self) -> Array:
        """``(4, C, T + 1)``: the alignment of every cell at every end time (see :meth:`alignment`)."""
        t1, cells = self.DT.shape
        ci = np.repeat(np.arange(cells), t1)
        ti = np.tile(np.arange(t1), cells)
        out = self.alignment(ci, ti)
        out[:, ti < self.dur[ci]] = np.array([1.0, 0.0, 0.0, 0.0])[:, None]  # no window: identity
        return out.reshape(4, cells, t1)

    @property
    def cos(self) -> Array:
        return np.asarray(self.alignments[0])

    @property
    def sin(self) -> Array:
        return np.asarray(self.alignments[1])

    @property
    def tx(self) -> Array:
        return np.asarray(self.alignments[2])

    @property
    def tz(self) -> Array:
        return np.asarray(self.alignments[3])


def interpretation(
    x: Array,
    inst: Instances,
    cell_inst: IntArray,
    cell_dur: IntArray,
    rate: float,
    context: int = 0,
    rigid: bool = False,
) -> Interpretation:
    """Eq. 1-2 for every cell and every end time: one matrix product per duration.

    ``x``: ``(T, P, 3)`` the input cloud at ``rate``. ``context`` (frames) extends each comparison by
    the input and the source control around the segment on both sides (the input's ends repeated),
    so a segment is also judged by the motion leading into and out of it (0 = the paper's D).
    ``rigid``: the alignment is the full 3-D rigid transform (Procrustes: nine matrix products per
    duration and one 3x3 SVD per cell and end time) instead of rotation about +Y + floor translation."""
    if rigid:
        return _rigid_interpretation(x, inst, cell_inst, cell_dur, rate, context)
    t_len, p, _ = x.shape
    x = pad_edges(x, context)
    cells = cell_inst.shape[0]
    # written once below: the first d columns of a duration-d row (no window yet) and rows longer
    # than the input are infinite in D and zero in the cross-correlations (identity alignment)
    DT = np.empty((t_len + 1, cells))
    CT = np.empty((t_len + 1, cells))
    ST = np.empty((t_len + 1, cells))
    sum_a = np.zeros((cells, 2))
    n_pts_c = ((cell_dur + 2 * context) * p).astype(np.float64)
    sums = _WindowSums.of(x)
    for d in np.unique(cell_dur):
        d = int(d)
        rows = np.flatnonzero(cell_dur == d)
        # cells sorted by duration: the rows of one duration are a contiguous block (basic slices)
        blk = slice(int(rows[0]), int(rows[-1]) + 1) if rows[-1] - rows[0] + 1 == rows.size else rows
        head = min(d, t_len + 1)
        DT[:head, blk] = np.inf
        CT[:head, blk] = 0.0
        ST[:head, blk] = 0.0
        if d > t_len:
            continue
        a = stretched_templates(inst, cell_inst[rows], d, rate, context)  # (n, d + 2c, P, 3)
        sum_a[blk] = _duration_block(
            x, sums, a, d, t_len, rate, context, DT[d:, blk], CT[d:, blk], ST[d:, blk]
        )
    return Interpretation(
        DT, CT, ST, sum_a, n_pts_c, cell_dur.astype(np.intp), context, np.stack((sums.x, sums.z), -1)
    )


@dataclass(frozen=True, slots=True)
class _WindowSums:
    """Cumulative sums over the frames of an input cloud ``(T, P, 3)`` (``(T + 1,)`` each, 0 first):
    of its points' ``x``, of their ``z`` and of their squared norms; any window's sums in O(1)."""

    x: Array
    z: Array
    sq: Array

    @classmethod
    def of(cls, x: Array) -> _WindowSums:
        zero = np.zeros(1)
        xx, xz, xy = x[..., 0], x[..., 2], x[..., 1]
        return cls(
            np.concatenate((zero, np.cumsum(xx.sum(1)))),
            np.concatenate((zero, np.cumsum(xz.sum(1)))),
            np.concatenate((zero, np.cumsum((xx**2 + xz**2 + xy**2).sum(1)))),
        )


_SCRATCH = threading.local()


def _scratch(name: str, shape: tuple[int, int]) -> Array:
    """A C-contiguous ``shape`` view of this thread's scratch buffer ``name``, kept between calls
    (the products of :func:`_duration_block` are 1-3 MB each: fresh ones cost page faults)."""
    size = shape[0] * shape[1]
    buf = getattr(_SCRATCH, name, None)
    if buf is None or buf.size < size:
        buf = np.empty(max(size, 1 << 18))
        setattr(_SCRATCH, name, buf)
    return np.asarray(buf[:size].reshape(shape))


def _duration_block(
    x: Array,
    sums: _WindowSums,
    a: Array,
    d: int,
    t_len: int,
    rate: float,
    context: int,
    d_out: Array,
    c_out: Array,
    s_out: Array,
) -> Array:
    """Eq. 1-2 for the ``n`` cells of duration ``d`` (templates ``a (n, d + 2c, P, 3)``) against every
    window of the padded input ``x``: into ``d_out`` the distances ``(T + 1 - d, n)`` (m²·s,
    time-major) after the best rotation about +Y and floor translation, into ``c_out`` and ``s_out``
    (same shape) their cross-correlations; returns the templates' floor sums ``(n, 2)``."""
    n, p = a.shape[0], x.shape[1]
    c2 = 2 * context
    n_pts = (d + c2) * p
    # every term is scaled by 1 / (P rate) up front, so D comes out in m^2 s without another pass
    scale = 1.0 / (p * rate)
    a = a.reshape(n, n_pts, 3)
    sa = a.sum(1)  # (n, 3)
    # templates centred on the floor (their cross-correlation with any window is the centred one)
    # and the windows (nw, N) flattened like the templates: frame-major, then point
    nw = x.shape[0] - (d + c2) + 1
    # centred (n, N, 2) laid out (2, n, N), as NumPy's gather of [x, z] gives it (its reduction
    # below then sums in the same order)
    centred = np.empty((2, n, n_pts)).transpose(1, 2, 0)
    lhs, rhs = np.empty((2 * n, n_pts)), np.empty((2 * nw, n_pts))
    lhs_y, rhs_y = np.empty((n, n_pts + 2)), np.empty((nw, n_pts + 2))
    ready = compiled_ready()
    operands = duration_operands if ready else _operands_numpy
    operands(a, sa, np.ascontiguousarray(x), scale, centred, lhs, rhs, lhs_y, rhs_y)
    ends = np.arange(d, t_len + 1)
    e2 = ends + c2
    sx, sz = sums.x[e2] - sums.x[ends - d], sums.z[e2] - sums.z[ends - d]
    # one product gives the four planar cross terms: rows [ax; az], columns [wx | wz]
    g = np.matmul(lhs, rhs.T, out=_scratch("g", (2 * n, 2 * nw)))  # (2n, 2nw)
    # the rest of the residual in one more product: -2 ay.wy + the template's and the
    # window's own centred sums of squares (extra columns of ones)
    own_a = (centred**2).sum((1, 2)) + (a[..., 1] ** 2).sum(1)
    own_w = sums.sq[e2] - sums.sq[ends - d] - (sx**2 + sz**2) / n_pts
    lhs_y[:, n_pts] = own_a * scale
    lhs_y[:, n_pts + 1] = scale
    rhs_y[:, n_pts] = 1.0
    rhs_y[:, n_pts + 1] = own_w
    # c = ax.wx + az.wz, s = az.wx - ax.wz and D = max(0, rest - 2 |(c, s)|) in one compiled pass
    rest = np.matmul(lhs_y, rhs_y.T, out=_scratch("rest", (n, nw)))
    (residual_block if ready else _residual_numpy)(g, rest, d_out, c_out, s_out)
    return np.asarray(sa[:, [0, 2]])


def _operands_numpy(
    a: Array,
    sa: Array,
    x: Array,
    scale: float,
    centred: Array,
    lhs: Array,
    rhs: Array,
    lhs_y: Array,
    rhs_y: Array,
) -> None:
    """:func:`engines.control.kernels.duration_operands` in NumPy (its twin,
    :mod:`engines.control.tier`): the same arguments and outputs, each value the same single
    operation, so the same bits."""
    n, npt_all = a.shape[0], a.shape[1]
    length = npt_all // x.shape[1]
    nw = x.shape[0] - length + 1
    np.subtract(a[..., 0], (sa[:, 0] / npt_all)[:, None], out=centred[..., 0])
    np.subtract(a[..., 2], (sa[:, 2] / npt_all)[:, None], out=centred[..., 1])
    np.multiply(centred[..., 0], scale, out=lhs[:n])
    np.multiply(centred[..., 1], scale, out=lhs[n:])
    np.multiply(a[..., 1], -2.0 * scale, out=lhs_y[:, :npt_all])
    # the windows (nw, L, P, 3), flattened frame-major then point
    win = np.lib.stride_tricks.sliding_window_view(x, length, axis=0).transpose(0, 3, 1, 2)
    rhs[:nw] = win[..., 0].reshape(nw, npt_all)
    rhs[nw:] = win[..., 2].reshape(nw, npt_all)
    rhs_y[:, :npt_all] = win[..., 1].reshape(nw, npt_all)


def _residual_numpy(g: Array, rest: Array, d_out: Array, c_out: Array, s_out: Array) -> None:
    """:func:`engines.control.kernels.residual_block` in NumPy (its twin,
    :mod:`engines.control.tier`): ``c``, ``s`` and ``D = max(0, rest - 2 |(c, s)|)`` by the same
    operations in the same order, written time-major."""
    n, nw = rest.shape
    c = g[:n, :nw] + g[n:, nw:]
    s = g[n:, :nw] - g[:n, nw:]
    r = c * c
    r += s * s
    np.sqrt(r, out=r)
    r *= -2.0
    r += rest
    np.maximum(r, 0.0, out=r)
    c_out[...] = c.T
    s_out[...] = s.T
    d_out[...] = r.T


def _rigid_interpretation(
    x: Array, inst: Instances, cell_inst: IntArray, cell_dur: IntArray, rate: float, context: int
) -> Interpretation:
    """:func:`interpretation` with full 3-D rigid alignments (see there)."""
    t_len, p, _ = x.shape
    c2 = 2 * context
    x = pad_edges(x, context)
    cells = cell_inst.shape[0]
    DT = np.full((t_len + 1, cells), np.inf)
    D = DT.T
    rot = np.zeros((cells, t_len + 1, 3, 3))
    rot[...] = np.eye(3)
    trans = np.zeros((cells, t_len + 1, 3))
    zero = np.zeros((1, 3))
    per_frame = x.sum(1)  # (T + 2c, 3)
    cs = np.concatenate((zero, np.cumsum(per_frame, 0)))
    cs_sq = np.concatenate(([0.0], np.cumsum((x**2).sum((1, 2)))))
    for d in np.unique(cell_dur):
        d = int(d)
        if d > t_len:
            continue
        rows = np.flatnonzero(cell_dur == d)
        a = stretched_templates(inst, cell_inst[rows], d, rate, context)  # (n, d + 2c, P, 3)
        n, n_pts = len(rows), (d + c2) * p
        a_flat = a.reshape(n, -1, 3)
        w = np.lib.stride_tricks.sliding_window_view(x, d + c2, axis=0)  # (nw, P, 3, d + 2c)
        w = w.transpose(0, 3, 1, 2).reshape(w.shape[0], -1, 3)  # (nw, n_pts, 3)
        ends = np.arange(d, t_len + 1)
        e2 = ends + c2
        sw = cs[e2] - cs[ends - d]  # (nw, 3)
        sww = cs_sq[e2] - cs_sq[ends - d]
        sa = a_flat.sum(1)  # (n, 3)
        saa = (a_flat**2).sum((1, 2))
        # centred cross-covariances h[c, t] = sum a w^T - sa sw^T / n_pts: nine (n, nw) products
        h = np.empty((n, ends.size, 3, 3))
        for i in range(3):
            for j in range(3):
                h[:, :, i, j] = a_flat[:, :, i] @ w[:, :, j].T - np.outer(sa[:, i], sw[:, j]) / n_pts
        r, best = rotation_from_covariance(h)
        res = (saa - (sa**2).sum(1) / n_pts)[:, None] + (sww - (sw**2).sum(1) / n_pts)[None] - 2 * best
        np.maximum(res, 0.0, out=res)
        D[rows, d:] = res / (p * rate)
        rot[rows, d:] = r
        trans[rows, d:] = sw[None] / n_pts - np.einsum("ctij,cj->cti", r, sa / n_pts)
    empty = np.zeros((t_len + 1, cells))
    return Interpretation(
        DT,
        empty,
        empty,
        np.zeros((cells, 2)),
        ((cell_dur + c2) * p).astype(np.float64),
        cell_dur.astype(np.intp),
        context,
        np.zeros((t_len + c2 + 1, 2)),
        rot,
        trans,
    )


def apply_constraints(
    D: Array, cell_inst: IntArray, cell_dur: IntArray, constraints: list[tuple[int, int]]
) -> None:
    """Make illegal (in place) every cell of another instance covering a constrained frame:
    for ``(s, t)``, cells ``(r, d)`` with ``r != s`` ending at ``u`` with ``u - d <= t < u``."""
    t_len = D.shape[1] - 1
    for s, t in constraints:
        other = np.flatnonzero(cell_inst != s)
        for d in np.unique(cell_dur[other]):
            rows = other[cell_dur[other] == d]
            lo, hi = t + 1, min(t + int(d), t_len)
            if lo <= hi:
                D[rows, lo : hi + 1] = np.inf


def cost_to_go(D: Array, cell_dur: IntArray) -> Array:
    """``(T + 1,)`` an admissible bound of the cost from frame ``t`` to the end: the best tiling of
    ``[t, T)`` by interpretation distance alone (continuity is never negative). ``D``: ``(C, T + 1)``
    (:attr:`Interpretation.D`, whose transpose is contiguous: no copy); ``cell_dur``: ``(C,)``
    sorted ascending."""
    if np.any(np.diff(cell_dur) < 0):
        raise ValueError("cells must be sorted by duration (see legal_cells)")
    if not compiled_ready():
        return _cost_to_go_numpy(D, np.asarray(cell_dur))
    return np.asarray(
        kernel_cost_to_go(np.ascontiguousarray(D.T, dtype=np.float64), np.asarray(cell_dur, dtype=np.int64))
    )


def _cost_to_go_numpy(D: Array, cell_dur: IntArray) -> Array:
    """:func:`engines.control.kernels.cost_to_go` in NumPy (its twin, :mod:`engines.control.tier`):
    per duration the best cell ending at each time, then the tiling from the end; the same minima
    of the same sums, so the same bits."""
    t_len = D.shape[1] - 1
    durs, first = np.unique(cell_dur, return_index=True)
    bounds = np.append(first, cell_dur.shape[0])
    best = np.stack([D[bounds[g] : bounds[g + 1]].min(axis=0) for g in range(durs.size)])  # (G, T + 1)
    F = np.full(t_len + 1, np.inf)
    F[t_len] = 0.0
    for t in range(t_len - 1, -1, -1):
        ends = t + durs
        ok = ends <= t_len
        if ok.any():
            e = ends[ok]
            F[t] = np.min(best[np.flatnonzero(ok), e] + F[e])
    return F


@dataclass(slots=True)
class DPResult:
    """A solution of the DP: the cells in order, their end frames and the score terms."""

    score: float
    cells: IntArray
    ends: IntArray
    expanded: int
    interpretation: float
    continuity: float


def solve(
    interp: Interpretation,
    inst: Instances,
    cell_inst: IntArray,
    cell_dur: IntArray,
    k: float,
    *,
    beam: float | None = None,
    max_cells: tuple[int, int] | None = None,
    upper_bound: float | None = None,
    to_go: Array | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> DPResult:
    """The forward DP (Eq. 6-8) with optional beam (width ``beam``, score units) and exact
    branch-and-bound pruning against ``upper_bound`` with the admissible ``to_go`` bound.

    ``max_cells = (predecessors, successors)`` caps the cells processed at each boundary (a beam by
    count as well as by width): the best predecessors by score, the best successors by their
    interpretation distance plus the bound of the cost still to come.

    Raises :class:`Infeasible` when no legal tiling exists and :class:`InterruptedError` when
    ``should_stop()`` turns true."""
    D = interp.D
    cells, t1 = D.shape
    t_len = t1 - 1
    # time-major (T + 1, C): a boundary's cells are one contiguous row
    Q, back = _workspace(t1, cells)
    if np.any(np.diff(cell_dur) < 0):
        raise ValueError("cells must be sorted by duration (see legal_cells)")
    if should_stop is not None and should_stop():
        raise InterruptedError
    expanded = int(
        forward(
            np.ascontiguousarray(interp.DT),
            np.ascontiguousarray(interp.CT),
            np.ascontiguousarray(interp.ST),
            interp.sum_a,
            interp.n_pts,
            interp.dur.astype(np.int64),
            interp.context,
            interp.cs,
            np.zeros((0, 0, 3, 3)) if interp.rot is None else interp.rot,
            np.zeros((0, 0, 3)) if interp.trans is None else interp.trans,
            interp.rigid,
            np.ascontiguousarray(inst.tails.reshape(inst.count, -1, 3)),
            np.ascontiguousarray(inst.heads.reshape(inst.count, -1, 3)),
            cell_inst.astype(np.int64),
            k / inst.tails.shape[1],
            np.inf if beam is None else float(beam),
            0 if max_cells is None else int(max_cells[0]),
            0 if max_cells is None else int(max_cells[1]),
            np.inf if upper_bound is None else upper_bound * (1 + 1e-9) + 1e-12,
            np.zeros(t1) if to_go is None else np.ascontiguousarray(to_go, dtype=np.float64),
            Q,
            back,
        )
    )
    cells_arr, ends_arr = _best_path(Q, back, cell_dur)
    score = float(Q[t_len, cells_arr[-1]])
    interp_term = float(D[cells_arr, ends_arr].sum())
    return DPResult(score, cells_arr, ends_arr, expanded, interp_term, score - interp_term)


_WORK = threading.local()


def _workspace(t1: int, cells: int) -> tuple[Array, npt.NDArray[np.int64]]:
    """This thread's score and back-pointer tables ``(T + 1, C)`` for :func:`solve`: ``Q`` all
    ``inf``, ``back`` as left (the kernel writes it wherever it writes a score, and only those
    entries are read). Kept between calls: fresh 2-5 MB tables cost more in page faults than a fill."""
    q = getattr(_WORK, "q", None)
    b = getattr(_WORK, "back", None)
    if q is None or b is None or q.shape != (t1, cells):
        q = np.empty((t1, cells))
        b = np.empty((t1, cells), dtype=np.int64)
        _WORK.q, _WORK.back = q, b
    q.fill(np.inf)
    return q, b


def _best_path(Q: Array, back: npt.NDArray[np.int64], cell_dur: IntArray) -> tuple[IntArray, IntArray]:
    """The cells of the best tiling and their end frames, in order (back-tracked from the best score
    at the last frame); :class:`Infeasible` when there is none."""
    t_len = Q.shape[0] - 1
    final = Q[t_len]
    if not np.isfinite(final).any():
        raise Infeasible("no sequence of segments within the stretch bounds and constraints tiles the input")
    c = int(np.argmin(final))
    path_cells, path_ends = [], []
    t = t_len
    while c >= 0:
        path_cells.append(c)
        path_ends.append(t)
        prev = int(back[t, c])
        t -= int(cell_dur[c])
        c = prev
    return np.array(path_cells[::-1], dtype=np.intp), np.array(path_ends[::-1], dtype=np.intp)


def typical_segment_cost(D: Array) -> float:
    """The median over cells of their best interpretation distance anywhere in the input (beam unit)."""
    best = D.min(axis=1)
    best = best[np.isfinite(best)]
    return float(np.median(best)) if best.size else 1.0


# ----------------------------------------------------------------------------------- re-timing


@dataclass(slots=True)
class Timed:
    """A re-timed solution at the full rate: per segment its instance, boundaries and alignment."""

    score: float
    interpretation: float
    continuity: float
    instances: IntArray
    bounds: IntArray  # (L + 1,) frames at the full rate, 0 ... T
    cos: Array
    sin: Array
    tx: Array
    tz: Array
    D: Array
    C: Array
    rot: Array | None = None  # (L, 3, 3) with rigid (3-D) alignment: the segments' rotations
    trans: Array | None = None  # (L, 3) and translations (cos/sin/tx/tz then hold their floor part)


def retime(
    x: Array,
    inst: Instances,
    seq: IntArray,
    coarse_bounds: Array,
    k: float,
    rate: float,
    stretch_s: float | None,
    stretch_ratio: float | None,
    window: int,
    constraints: list[tuple[int, float]] | None = None,
    context: int = 0,
    rigid: bool = False,
) -> Timed:
    """The constrained DP at the full rate: the instances ``seq`` are fixed, each boundary moves
    within ``+-window`` frames of ``coarse_bounds`` (full-rate frames; first 0 and last ``T`` fixed)
    and durations stay within the stretch bounds.

    ``x``: ``(T, P, 3)`` the input at ``rate``; ``constraints``: ``(segment index, frame)`` pairs the
    segment must keep covering; ``rigid``: full 3-D rigid alignments (see :func:`interpretation`)."""
    n_seg = seq.shape[0]
    flat_seg, flat_a, flat_b = _retime_states(
        x.shape[0], inst, seq, coarse_bounds, rate, stretch_s, stretch_ratio, window, constraints
    )
    # interpretation of every state
    al = _StateAlignments.of(x, inst, seq[flat_seg], flat_a, flat_b, rate, context, rigid)
    offs = np.searchsorted(flat_seg, np.arange(n_seg + 1)).astype(np.intp)
    score, idx = _chain(al, inst, seq, offs, flat_a, flat_b, k)
    bounds = np.concatenate((flat_a[idx], flat_b[idx[-1:]]))
    # per-boundary continuity of the chosen states
    sel_rot = None if al.rot is None else al.rot[idx]
    sel_trans = None if al.trans is None else al.trans[idx]
    if sel_rot is not None and sel_trans is not None:
        # the floor part of each rigid transform, for reports: yaw of the rotated +Z axis
        fwd = sel_rot[:, :, 2]
        yaw = np.arctan2(fwd[:, 0], fwd[:, 2])
        al.cos[idx], al.sin[idx] = np.cos(yaw), np.sin(yaw)
        al.tx[idx], al.tz[idx] = sel_trans[:, 0], sel_trans[:, 2]
    q_pts = inst.tails.shape[1]
    y = al.place(inst.tails[seq[:-1]], idx[:-1])
    h = al.place(inst.heads[seq[1:]], idx[1:])
    C = ((y - h) ** 2).sum(axis=(1, 2)) / q_pts if n_seg > 1 else np.zeros(0)
    Dsel = al.D[idx]
    return Timed(
        score,
        float(Dsel.sum()),
        float(k * C.sum()),
        seq.copy(),
        bounds,
        al.cos[idx],
        al.sin[idx],
        al.tx[idx],
        al.tz[idx],
        Dsel,
        C,
        sel_rot,
        sel_trans,
    )


def _retime_states(
    t_len: int,
    inst: Instances,
    seq: IntArray,
    coarse_bounds: Array,
    rate: float,
    stretch_s: float | None,
    stretch_ratio: float | None,
    window: int,
    constraints: list[tuple[int, float]] | None,
) -> tuple[IntArray, IntArray, IntArray]:
    """Every segment's states, segment by segment, each segment's ordered by start then end:
    ``(segment, start, end)`` ``(m,)`` full-rate frames with each boundary within ``+-window`` of the
    coarse one, a legal duration (else the coarse one's own) and every constraint on the segment
    covered. All segments at once: a ``(L, W, W)`` grid of (start, end) options (``W = 2 window + 1``)."""
    n_seg = seq.shape[0]
    cb = np.round(np.asarray(coarse_bounds, dtype=np.float64)).astype(np.intp)
    cb[0], cb[-1] = 0, t_len
    width = 2 * window + 1
    # (L + 1, W) the options of each boundary (padded with -1): the first and last are fixed
    lo = np.maximum(1, cb - window)
    hi = np.minimum(t_len - 1, cb + window)
    lo[0], hi[0], lo[-1], hi[-1] = 0, 0, t_len, t_len
    opt = lo[:, None] + np.arange(width)[None, :]
    valid = opt <= hi[:, None]
    a = np.broadcast_to(opt[:-1, :, None], (n_seg, width, width))
    b = np.broadcast_to(opt[1:, None, :], (n_seg, width, width))
    both = valid[:-1, :, None] & valid[1:, None, :]
    d = b - a
    # the legal durations of each segment's instance (legal_cells' bounds, all segments at once)
    lengths_s = inst.length[seq] / inst.fps
    d_lo, d_hi = _legal_range(lengths_s, rate, stretch_s, stretch_ratio)
    ok = both & (d >= d_lo[:, None, None]) & (d <= d_hi[:, None, None])
    for i in np.flatnonzero(~ok.any(axis=(1, 2))):  # the coarse solution's own duration stays possible
        forward = both[i] & (d[i] >= 1)  # a segment lasts at least one frame
        di = d[i][forward]
        if di.size == 0:
            continue  # no boundary options at all: no state (Infeasible in the chain)
        ok[i] = forward & (d[i] == di[np.argmin(np.abs(di - (cb[i + 1] - cb[i])))])
    for seg_i, frame in constraints or []:
        if 0 <= seg_i < n_seg:
            ok[seg_i] &= (a[seg_i] <= frame) & (frame < b[seg_i])
    seg, ia, ib = np.nonzero(ok)
    return seg.astype(np.intp), a[seg, ia, ib].astype(np.intp), b[seg, ia, ib].astype(np.intp)


def _legal_range(
    lengths_s: Array, rate: float, stretch_s: float | None, stretch_ratio: float | None
) -> tuple[IntArray, IntArray]:
    """``(N,)`` the shortest and longest legal durations (frames at ``rate``) of segments of
    ``lengths_s (N,)`` seconds (:func:`legal_cells` takes every duration between them)."""
    nominal = lengths_s * rate
    if stretch_ratio is not None:
        lo, hi = nominal * (1 - stretch_ratio), nominal * (1 + stretch_ratio)
    else:
        s = 0.15 if stretch_s is None else stretch_s
        lo, hi = nominal - s * rate, nominal + s * rate
    lo_i = np.maximum(1, np.ceil(lo - 1e-9)).astype(np.intp)
    hi_i = np.floor(hi + 1e-9).astype(np.intp)
    near = np.maximum(1, np.round(nominal)).astype(np.intp)
    return np.minimum(lo_i, near), np.maximum(hi_i, near)


@dataclass(slots=True)
class _StateAlignments:
    """Per re-timing state (``(m,)`` arrays): the interpretation distance ``D`` of its instance
    stretched over ``[start, end)``, and its alignment: rotation about +Y (``cos``, ``sin``) and floor
    translation (``tx``, ``tz``), or with ``rigid`` a full rotation ``rot (m, 3, 3)`` and
    translation ``trans (m, 3)``."""

    D: Array
    cos: Array
    sin: Array
    tx: Array
    tz: Array
    rot: Array | None
    trans: Array | None

    @classmethod
    def of(
        cls,
        x: Array,
        inst: Instances,
        state_inst: IntArray,
        start: IntArray,
        end: IntArray,
        rate: float,
        context: int,
        rigid: bool,
    ) -> _StateAlignments:
        """Align every state's stretched template to its input window: the floor alignment in one
        compiled pass over the states (:func:`engines.control.kernels.state_alignments`), the rigid
        one (or a control cloud not ``(F, P, 3)`` float64) one duration at a time."""
        m = start.size
        xp = pad_edges(x, context)
        p = x.shape[1]
        durs = end - start
        ctl = inst.control
        if compiled_ready() and not rigid and ctl.ndim == 3 and ctl.dtype == np.float64 and ctl.shape[1] == p:
            out = np.empty((5, m))
            bounds = (
                inst.pair_bounds[state_inst].astype(np.int64)
                if context and inst.pair_bounds is not None
                else np.zeros((0, 2), dtype=np.int64)
            )
            state_alignments(
                np.ascontiguousarray(ctl),
                inst.start[state_inst].astype(np.int64),
                inst.length[state_inst].astype(np.int64),
                bounds,
                np.ascontiguousarray(xp, dtype=np.float64),
                start.astype(np.int64),
                durs.astype(np.int64),
                int(context),
                float(p * rate),
                np.lexsort((start, durs, state_inst)).astype(np.int64),
                out,
            )
            return cls(out[0], out[1], out[2], out[3], out[4], None, None)
        al = cls(np.full(m, np.inf), np.ones(m), np.zeros(m), np.zeros(m), np.zeros(m), None, None)
        if rigid:
            al.rot, al.trans = np.repeat(np.eye(3)[None], m, 0), np.zeros((m, 3))
        for d in np.unique(durs):
            rows = np.flatnonzero(durs == d)
            tmpl = stretched_templates(inst, state_inst[rows], int(d), rate, context)
            win = xp[start[rows, None] + np.arange(d + 2 * context)[None, :]]
            if al.rot is not None and al.trans is not None:
                res, r, t = paired_procrustes(win.reshape(rows.size, -1, 3), tmpl.reshape(rows.size, -1, 3))
                al.rot[rows], al.trans[rows] = r, t
                al.D[rows] = res / (p * rate)
                continue
            res, c, s, tx_, tz_ = paired_alignment(
                win.reshape(rows.size, -1, 3), tmpl.reshape(rows.size, -1, 3)
            )
            al.D[rows], al.cos[rows], al.sin[rows] = res / (p * rate), c, s
            al.tx[rows], al.tz[rows] = tx_, tz_
        return al

    def place(self, points: Array, rows: IntArray) -> Array:
        """``points (n, ..., 3)`` moved by the alignments of states ``rows (n,)``."""
        return place_points(
            points,
            self.cos[rows],
            self.sin[rows],
            self.tx[rows],
            self.tz[rows],
            None if self.rot is None else self.rot[rows],
            None if self.trans is None else self.trans[rows],
        )


def _chain(
    al: _StateAlignments,
    inst: Instances,
    seq: IntArray,
    offs: IntArray,
    start: IntArray,
    end: IntArray,
    k: float,
) -> tuple[float, IntArray]:
    """The DP over the segments' states (``offs (L + 1,)``: where each segment's states begin):
    distance plus continuity between consecutive aligned segments, a state following one that ends
    where it starts. Returns the best score and the chosen state of every segment.

    The placed tails and heads of all states at once; per boundary one matrix product ``2 Y H^T``
    (BLAS, as ever: the continuity to the bit); the DP itself compiled
    (:func:`engines.control.kernels.retime_chain`)."""
    n_seg = seq.shape[0]
    q_pts = inst.tails.shape[1]
    if np.any(np.diff(offs) == 0):
        raise Infeasible("re-timing found no legal boundaries")
    seg = np.repeat(np.arange(n_seg), np.diff(offs))
    m = seg.size
    y = al.place(inst.tails[seq[seg]], np.arange(m)).reshape(m, -1)
    h = al.place(inst.heads[seq[seg]], np.arange(m)).reshape(m, -1)
    yn, hn = (y**2).sum(1), (h**2).sum(1)
    blocks = [2 * y[offs[i - 1] : offs[i]] @ h[offs[i] : offs[i + 1]].T for i in range(1, n_seg)]
    G = np.concatenate([g.ravel() for g in blocks]) if blocks else np.zeros(0)
    g_offs = np.concatenate(([0], np.cumsum([g.size for g in blocks], dtype=np.int64)))
    chosen = np.empty(n_seg, dtype=np.int64)
    chain = retime_chain if compiled_ready() else _chain_numpy
    score = float(
        chain(
            np.ascontiguousarray(al.D, dtype=np.float64),
            offs.astype(np.int64),
            start.astype(np.int64),
            end.astype(np.int64),
            yn,
            hn,
            G,
            g_offs,
            k / q_pts,
            chosen,
        )
    )
    if not np.isfinite(score):
        raise Infeasible("re-timing found no legal boundaries")
    return score, chosen.astype(np.intp)


def _chain_numpy(
    D: Array,
    offs: npt.NDArray[np.int64],
    start: npt.NDArray[np.int64],
    end: npt.NDArray[np.int64],
    yn: Array,
    hn: Array,
    G: Array,
    g_offs: npt.NDArray[np.int64],
    kq: float,
    chosen: npt.NDArray[np.int64],
) -> float:
    """:func:`engines.control.kernels.retime_chain` in NumPy (its twin, :mod:`engines.control.tier`;
    the same arguments, the same operations in their order, the first of equal totals: the same
    bits). Returns the best score (``inf``: none) and writes the chosen states into ``chosen``."""
    n_seg = offs.shape[0] - 1
    m = D.shape[0]
    Q = np.empty(m)
    back = np.zeros(m, dtype=np.int64)
    Q[offs[0] : offs[1]] = D[offs[0] : offs[1]]
    for i in range(1, n_seg):
        p0, p1, c0, c1 = int(offs[i - 1]), int(offs[i]), int(offs[i]), int(offs[i + 1])
        npv, nc = p1 - p0, c1 - c0
        g0 = int(g_offs[i - 1])
        cont = (yn[p0:p1, None] + hn[None, c0:c1]) - G[g0 : g0 + npv * nc].reshape(npv, nc)
        tot = Q[p0:p1, None] + kq * np.maximum(cont, 0.0)
        tot[end[p0:p1, None] != start[None, c0:c1]] = np.inf
        arg = np.argmin(tot, axis=0)
        Q[c0:c1] = tot[arg, np.arange(nc)] + D[c0:c1]
        back[c0:c1] = p0 + arg
    lo = int(offs[n_seg - 1])
    last = lo + int(np.argmin(Q[lo : int(offs[n_seg])]))
    score = float(Q[last])
    for i in range(n_seg - 1, -1, -1):
        chosen[i] = last
        last = int(back[last])
    return score
