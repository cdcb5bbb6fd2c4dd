"""The forward pass of the segment DP (Hsu et al. 2004, Eq. 6-8) as one compiled kernel (numba).

Written by hand with numba rather than numpy: the pass is a sequence of small, data-dependent steps
per boundary (select the predecessors and successors a beam or a bound keeps, align their target
points, find each successor's best predecessor with an early exit), and in numpy their per-call
overhead dominated (about 15 ms per anytime stage on the salsa database). Compiled with
``cache=True``: the first call in a fresh environment compiles (a few seconds, see
``bench/control.py``'s ``first_call_s``), later processes load the machine code from numba's
cache (:mod:`motion.jitcache`); ``segue warm`` (:mod:`engines.control.warm`) compiles them ahead of
the first request. The secondary kernels below the forward pass (sampling, interpretation operands,
cost to go, re-timing) have exact NumPy twins in :mod:`engines.control.dp`, which a process runs
until ``segue warm`` compiled them (:mod:`engines.control.tier`).

Exactness: every successor ``i`` scans its predecessors in increasing score ``q_j``; since
continuity is never negative, once ``q_j`` reaches its best total so far (or what the upper bound
leaves for it), no later predecessor can win, so the scan stops there. The result is the optimum of
the candidates kept (all of them when neither beam nor caps are given).
"""

from __future__ import annotations

import numpy as np

from motion.jitcache import configure

configure()  # numba's cache outside the package, before numba is imported

from numba import njit  # noqa: E402

INF = np.inf


BLOCK = 32
"""Predecessors screened at once by their centroid bound (one vectorized pass, no branches)."""

SLACK = 1e-9
"""Relative slack of that screen (no division): it passes a superset of the predecessors the exact
centroid test passes, which then runs unchanged."""


@njit(cache=True, nogil=True)
def cost_to_go(DT: np.ndarray, dur: np.ndarray) -> np.ndarray:
    """``(T + 1,)`` the best tiling of ``[t, T)`` by interpretation distance alone: ``DT (T + 1, C)``
    time-major distances (m²·s), ``dur (C,)`` the cells' durations sorted ascending (frames)."""
    t1, cells = DT.shape
    t_len = t1 - 1
    g_lo, g_hi = _runs(dur)
    ng = g_lo.shape[0]
    best = np.full((ng, t1), INF)  # per distinct duration, the best cell ending at each time
    for e in range(t1):
        for g in range(ng):
            m = INF
            for c in range(g_lo[g], g_hi[g]):
                if DT[e, c] < m:
                    m = DT[e, c]
            best[g, e] = m
    F = np.full(t1, INF)
    F[t_len] = 0.0
    for t in range(t_len - 1, -1, -1):
        m = INF
        for g in range(ng):
            e = t + dur[g_lo[g]]
            if e <= t_len:
                v = best[g, e] + F[e]
                if v < m:
                    m = v
        F[t] = m
    return F


@njit(cache=True, nogil=True)
def sample_frames(cloud: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """``cloud (F, P, 3)`` at fractional frame indices ``frames (n, L)``: ``(n, L, P, 3)``, linear
    and clamped (:func:`engines.control.points.sample_cloud`'s operations, to the bit, without its
    temporaries)."""
    nf, npt = cloud.shape[0], cloud.shape[1]
    n, length = frames.shape
    out = np.empty((n, length, npt, 3))
    top = max(nf - 2, 0)
    for r in range(n):
        for i in range(length):
            f = min(max(frames[r, i], 0.0), float(nf - 1))
            i0 = min(int(np.floor(f)), top)
            i1 = min(i0 + 1, nf - 1)
            a = f - i0
            b = 1 - a
            for p in range(npt):
                for k in range(3):
                    out[r, i, p, k] = cloud[i0, p, k] * b + cloud[i1, p, k] * a
    return out


@njit(cache=True, nogil=True)
def duration_operands(
    a: np.ndarray,
    sa: np.ndarray,
    x: np.ndarray,
    scale: float,
    centred: np.ndarray,
    lhs: np.ndarray,
    rhs: np.ndarray,
    lhs_y: np.ndarray,
    rhs_y: np.ndarray,
) -> None:
    """The operands of one duration's products (:func:`engines.control.dp._duration_block`), built
    in one pass each (the NumPy gathers and transposes they replace, to the bit).

    ``a (n, N, 3)``: the stretched templates (``N`` = frames x points, frame-major); ``sa (n, 3)``
    their sums; ``x (T', P, 3)``: the padded input, windows of ``N / P`` frames. Fills ``centred
    (n, N, 2)`` (the templates' ``x``, ``z`` minus their means), ``lhs (2n, N)`` (``[ax; az]``
    centred, times ``scale``), ``rhs (2 nw, N)`` (the windows' ``[wx; wz]``), and the first ``N``
    columns of ``lhs_y (n, N + 2)`` and ``rhs_y (nw, N + 2)`` (``-2 scale ay`` and ``wy``). The
    caller allocates them (NumPy's reductions and BLAS may sum in another order at another
    alignment)."""
    n, npt_all = a.shape[0], a.shape[1]
    p = x.shape[1]
    length = npt_all // p
    nw = x.shape[0] - length + 1
    m2 = -2.0 * scale
    for r in range(n):
        mx = sa[r, 0] / npt_all
        mz = sa[r, 2] / npt_all
        for k in range(npt_all):
            cx = a[r, k, 0] - mx
            cz = a[r, k, 2] - mz
            centred[r, k, 0] = cx
            centred[r, k, 1] = cz
            lhs[r, k] = cx * scale
            lhs[n + r, k] = cz * scale
            lhs_y[r, k] = a[r, k, 1] * m2
    for w in range(nw):
        for f in range(length):
            for q in range(p):
                k = f * p + q
                rhs[w, k] = x[w + f, q, 0]
                rhs[nw + w, k] = x[w + f, q, 2]
                rhs_y[w, k] = x[w + f, q, 1]


TILE = 64
"""Cells per tile of :func:`residual_block` (computed along time, then written time-major)."""


@njit(cache=True, nogil=True)
def residual_block(
    g: np.ndarray, rest: np.ndarray, d_out: np.ndarray, c_out: np.ndarray, s_out: np.ndarray
) -> None:
    """The interpretation distances of one duration from its products (one pass, no temporaries).

    ``g (2 n, 2 nw)``: centred templates ``[ax; az]`` (scaled) times windows ``[wx | wz]``;
    ``rest (n, nw)``: the residual without the rotation term (m²·s). Writes, time-major ``(nw, n)``,
    ``c_out = ax.wx + az.wz``, ``s_out = az.wx - ax.wz`` and ``d_out = max(0, rest - 2 |(c, s)|)``
    (the operations, in their order, of the NumPy expression this replaces: equal to the bit)."""
    n, nw = rest.shape
    tc = np.empty((TILE, nw))
    ts = np.empty((TILE, nw))
    td = np.empty((TILE, nw))
    for a0 in range(0, n, TILE):
        a1 = min(a0 + TILE, n)
        for u in range(a1 - a0):  # along time: contiguous, vectorized
            a = a0 + u
            for w in range(nw):
                c = g[a, w] + g[n + a, nw + w]
                s = g[n + a, w] - g[a, nw + w]
                r = np.sqrt(c * c + s * s) * -2.0 + rest[a, w]
                tc[u, w] = c
                ts[u, w] = s
                td[u, w] = r if r >= 0.0 else 0.0  # np.maximum(r, 0.0) for finite r
        for w in range(nw):  # then the tile's rows, time-major
            for u in range(a1 - a0):
                c_out[w, a0 + u] = tc[u, w]
                s_out[w, a0 + u] = ts[u, w]
                d_out[w, a0 + u] = td[u, w]


@njit(cache=True, nogil=True)
def _runs(dur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(first, end)`` cell of each run of equal durations in ``dur (C,)`` (sorted ascending)."""
    cells = dur.shape[0]
    ng = 0
    for c in range(cells):
        if c == 0 or dur[c] != dur[c - 1]:
            ng += 1
    lo = np.empty(ng, dtype=np.int64)
    hi = np.empty(ng, dtype=np.int64)
    g = -1
    for c in range(cells):
        if c == 0 or dur[c] != dur[c - 1]:
            g += 1
            lo[g] = c
        hi[g] = c + 1
    return lo, hi


@njit("void(float64[::1], int64, int64[::1], int64[::1])", cache=True, nogil=True)
def _argsort_stable(keys: np.ndarray, n: int, order: np.ndarray, tmp: np.ndarray) -> None:
    """``order[:n]`` = the indices of ``keys[:n]`` (no NaN) in increasing key order, ties in index
    order: the order ``np.argsort(keys[:n], kind="stable")`` gives, by a bottom-up merge sort
    (``tmp``: scratch of at least ``n``). Written out because numba's own ``argsort`` was about a
    fifth of the kernels' compile time (3 of ~15 CPU-s)."""
    for i in range(n):
        order[i] = i
    src, dst = order, tmp
    in_order = True
    width = 1
    while width < n:
        for lo in range(0, n, 2 * width):
            mid = min(lo + width, n)
            hi = min(lo + 2 * width, n)
            i, j, k = lo, mid, lo
            while i < mid and j < hi:
                if keys[src[j]] < keys[src[i]]:
                    dst[k] = src[j]
                    j += 1
                else:
                    dst[k] = src[i]
                    i += 1
                k += 1
            while i < mid:
                dst[k] = src[i]
                i += 1
                k += 1
            while j < hi:
                dst[k] = src[j]
                j += 1
                k += 1
        src, dst = dst, src
        in_order = not in_order
        width *= 2
    if not in_order:
        for i in range(n):
            order[i] = tmp[i]


@njit(
    "float64(float64[::1], int64, int64)", cache=True, nogil=True
)  # one signature: no literal-argument copies
def _select(work: np.ndarray, n: int, k: int) -> float:
    """The ``k``-th smallest (0-based) of ``work[:n]`` (no NaN), by quickselect in place."""
    lo, hi = 0, n - 1
    while lo < hi:
        pivot = work[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while work[i] < pivot:
                i += 1
            while work[j] > pivot:
                j -= 1
            if i <= j:
                work[i], work[j] = work[j], work[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return float(work[k])


SAMPLE = 64
"""Values sampled by :func:`_kth` to guess a threshold below which the wanted ones lie."""


@njit(
    "float64(float64[::1], int64, int64, float64[::1])", cache=True, nogil=True
)  # one signature: no literal-argument copies
def _kth(values: np.ndarray, n: int, k: int, work: np.ndarray) -> float:
    """The ``k``-th smallest (0-based) of ``values[:n]`` (no NaN); ``work`` ``(>= n,)`` scratch.

    For a small ``k`` of many values: a threshold from every ``n / SAMPLE``-th value (about twice the
    wanted fraction), the values at or below it gathered without branches, and the selection run on
    those alone when there are enough of them (else on all)."""
    if n >= 4 * SAMPLE and (k + 1) * 4 <= n:
        step = n // SAMPLE
        for i in range(SAMPLE):
            work[i] = values[i * step]
        rank = min(SAMPLE - 1, (2 * (k + 1) * SAMPLE) // n + 1)
        cut = _select(work, SAMPLE, rank)
        m = 0
        for i in range(n):
            v = values[i]
            work[m] = v
            m += 1 if v <= cut else 0
        if m > k:
            return _select(work, m, k)
    for i in range(n):
        work[i] = values[i]
    return _select(work, n, k)


@njit(cache=True, nogil=True)
def _transform(
    c: float, s: float, ma0: float, ma1: float, wx: float, wz: float
) -> tuple[float, float, float, float]:
    """``cos, sin, tx, tz`` of the alignment with cross terms ``(c, s)`` taking the template's floor
    mean ``(ma0, ma1)`` onto the window's ``(wx, wz)`` (the floor alignment of
    :meth:`engines.control.dp.Interpretation.alignment`)."""
    r = np.hypot(c, s)
    if r > 0:
        cth, sth = c / r, s / r
    else:
        cth, sth = 1.0, 0.0
    return cth, sth, wx - (cth * ma0 + sth * ma1), wz - (cth * ma1 - sth * ma0)


@njit(cache=True, nogil=True)
def forward(
    DT: np.ndarray,
    CT: np.ndarray,
    ST: np.ndarray,
    sum_a: np.ndarray,
    n_pts: np.ndarray,
    dur: np.ndarray,
    context: int,
    cs: np.ndarray,
    rot: np.ndarray,
    trans: np.ndarray,
    rigid: bool,
    tails: np.ndarray,
    heads: np.ndarray,
    cell_inst: np.ndarray,
    kq: float,
    beam: float,
    max_pred: int,
    max_succ: int,
    ub: float,
    F: np.ndarray,
    Q: np.ndarray,
    back: np.ndarray,
) -> int:
    """Fill ``Q (T + 1, C)`` (best score of a tiling of ``[0, t)`` whose last cell is ``c``; ``inf``
    when none is kept) and ``back`` (its predecessor cell, -1 first) and return the pairs evaluated
    (point sums begun).

    ``DT (T + 1, C)``, ``CT``/``ST`` the time-major distances and cross terms (a boundary's cells
    are one contiguous row), ``sum_a``, ``n_pts``, ``dur``, ``context``, ``cs``, ``rot``,
    ``trans``, ``rigid``: the interpretation (:class:`engines.control.dp.Interpretation`);
    ``tails``/``heads`` ``(N, Q, 3)``; ``kq`` the continuity weight per point; ``beam`` the width
    (``inf``: none); ``max_pred``, ``max_succ`` the caps per boundary (0: none); ``ub`` the upper
    bound (``inf``: none); ``F`` the admissible cost to go ``(T + 1,)``. ``Q`` must hold ``inf``
    on entry; ``back`` is written where ``Q`` is finite and read nowhere else.

    The hot loops call no function taking arrays (each such call costs atomic reference counts)."""
    t1, cells = DT.shape
    t_len = t1 - 1
    nq = tails.shape[1]
    # runs of equal duration: a boundary's successors of one duration are one slice of a row of DT
    g_lo, g_hi = _runs(dur)
    ng = g_lo.shape[0]
    # per cell, 1 / points and the template's floor mean (the alignment's translation)
    inv_n = np.empty(cells)
    ma = np.empty((cells, 2))
    for c in range(cells):
        inv_n[c] = 1.0 / n_pts[c]
        ma[c, 0] = sum_a[c, 0] * inv_n[c]
        ma[c, 1] = sum_a[c, 1] * inv_n[c]
    colmin = np.full(t1, INF)
    for c in range(cells):
        d = dur[c]
        if d <= t_len and DT[d, c] < INF:
            Q[d, c] = DT[d, c]
            back[d, c] = -1
            if DT[d, c] < colmin[d]:
                colmin[d] = DT[d, c]
    pairs = 0
    pred = np.empty(cells, dtype=np.int64)
    order_buf = np.empty(cells, dtype=np.int64)
    tmp_buf = np.empty(cells, dtype=np.int64)
    pq = np.empty(cells)
    succ = np.empty(cells, dtype=np.int64)
    skey = np.empty(cells)
    work = np.empty(cells)
    kept = cells if max_pred <= 0 else min(cells, max_pred)  # predecessors kept at most
    ytab = np.empty((kept, nq, 3))
    hbuf = np.empty((1, nq, 3))
    ybar = np.empty((kept, 3))
    # the predecessors' centroids by coordinate (score order), for the vectorized screen
    yx, yy, yz = np.empty(cells), np.empty(cells), np.empty(cells)
    passed = np.empty(BLOCK, dtype=np.bool_)
    kn = kq * nq
    for t in range(1, t_len):
        # predecessors: cells ending at t with a score within the bound and the beam (every
        # score at t is written once, and colmin[t] follows each: it is the row's minimum)
        qmin = colmin[t]
        if qmin == INF:
            continue
        npred = 0
        ft = F[t]
        qcap = qmin + beam
        for c in range(cells):
            q = Q[t, c]
            if q < INF and q + ft <= ub and q <= qcap:
                pred[npred] = c
                pq[npred] = q
                npred += 1
        if npred == 0:
            continue
        if max_pred > 0 and npred > max_pred:
            # the max_pred best by score (a selection, not a sort, of all of them)
            cut = _kth(pq, npred, max_pred - 1, work)
            m = 0
            for j in range(npred):
                if pq[j] <= cut and m < max_pred:
                    pred[m] = pred[j]
                    pq[m] = pq[j]
                    m += 1
            npred = m
        _argsort_stable(pq, npred, order_buf, tmp_buf)
        order = order_buf[:npred]
        ps = pred[order]
        qs = pq[order]
        qkept = qs[0]
        # successors: cells starting at t that can still improve a score within the limits
        # (branch-free compaction over one contiguous row slice per duration)
        nsucc = 0
        for g in range(ng):
            e = t + dur[g_lo[g]]
            if e > t_len:
                break
            fe = F[e]
            cb = colmin[e] + beam
            for c in range(g_lo[g], g_hi[g]):
                dc = DT[e, c]
                lower = qkept + dc
                keep = dc != INF and not (lower + fe > ub) and not (lower > cb)
                succ[nsucc] = c
                skey[nsucc] = dc + fe
                nsucc += 1 if keep else 0
        if nsucc == 0:
            continue
        if max_succ > 0 and nsucc > max_succ:
            cut = _kth(skey, nsucc, max_succ - 1, work)
            m = 0
            for i in range(nsucc):
                if skey[i] <= cut and m < max_succ:
                    succ[m] = succ[i]
                    m += 1
            nsucc = m
        # the predecessors' placed tails and their centroids
        for j in range(npred):
            c = ps[j]
            if rigid:  # the 3-D rigid alignment of this cell ending at t
                p = cell_inst[c]
                for a in range(nq):
                    for b in range(3):
                        ytab[j, a, b] = (
                            rot[c, t, b, 0] * tails[p, a, 0]
                            + rot[c, t, b, 1] * tails[p, a, 1]
                            + rot[c, t, b, 2] * tails[p, a, 2]
                            + trans[c, t, b]
                        )
            else:
                lo = max(t - dur[c], 0)
                wx = (cs[t + 2 * context, 0] - cs[lo, 0]) * inv_n[c]
                wz = (cs[t + 2 * context, 1] - cs[lo, 1]) * inv_n[c]
                cth, sth, tx, tz = _transform(CT[t, c], ST[t, c], ma[c, 0], ma[c, 1], wx, wz)
                p = cell_inst[c]
                for a in range(nq):
                    x, z = tails[p, a, 0], tails[p, a, 2]
                    ytab[j, a, 0] = cth * x + sth * z + tx
                    ytab[j, a, 1] = tails[p, a, 1]
                    ytab[j, a, 2] = -sth * x + cth * z + tz
            for b in range(3):
                ybar[j, b] = 0.0
                for a in range(nq):
                    ybar[j, b] += ytab[j, a, b] / nq
            yx[j], yy[j], yz[j] = ybar[j, 0], ybar[j, 1], ybar[j, 2]
        for i in range(nsucc):
            c = succ[i]
            e = t + dur[c]
            p = cell_inst[c]
            if rigid:
                for a in range(nq):
                    for b in range(3):
                        hbuf[0, a, b] = (
                            rot[c, e, b, 0] * heads[p, a, 0]
                            + rot[c, e, b, 1] * heads[p, a, 1]
                            + rot[c, e, b, 2] * heads[p, a, 2]
                            + trans[c, e, b]
                        )
            else:
                lo = max(e - dur[c], 0)
                wx = (cs[e + 2 * context, 0] - cs[lo, 0]) * inv_n[c]
                wz = (cs[e + 2 * context, 1] - cs[lo, 1]) * inv_n[c]
                cth, sth, tx, tz = _transform(CT[e, c], ST[e, c], ma[c, 0], ma[c, 1], wx, wz)
                for a in range(nq):
                    x, z = heads[p, a, 0], heads[p, a, 2]
                    hbuf[0, a, 0] = cth * x + sth * z + tx
                    hbuf[0, a, 1] = heads[p, a, 1]
                    hbuf[0, a, 2] = -sth * x + cth * z + tz
            dc = DT[e, c]
            h0, h1, h2 = 0.0, 0.0, 0.0
            for a in range(nq):
                h0 += hbuf[0, a, 0] / nq
                h1 += hbuf[0, a, 1] / nq
                h2 += hbuf[0, a, 2] / nq
            limit = ub - dc - F[e]  # a total above the bound is pruned anyway
            # this successor's best predecessor: a scan in increasing score; since continuity is
            # never negative, it stops at the first score at or above the best total so far (or
            # above what the bound leaves). Blocks of predecessors are screened at once by their
            # centroid bound; those passing go through the exact tests in order.
            best = INF
            arg = -1
            j0 = 0
            stop = False
            while j0 < npred and not stop:
                q = qs[j0]
                if q >= best or q > limit:
                    break
                n_blk = min(BLOCK, npred - j0)
                cap = min(best, limit)
                n_pass = 0
                base = max(j0, 0)  # known non-negative: contiguous vector loads, no gathers
                for u in range(n_blk):
                    d0 = yx[base + u] - h0
                    d1 = yy[base + u] - h1
                    d2 = yz[base + u] - h2
                    ok = not (kn * (d0 * d0 + d1 * d1 + d2 * d2) > (cap - qs[base + u]) * (1.0 + SLACK))
                    passed[u] = ok
                    n_pass += ok
                u = 0
                while n_pass > 0:
                    if not passed[u]:
                        u += 1
                        continue
                    n_pass -= 1
                    j = j0 + u
                    u += 1
                    q = qs[j]
                    if q >= best or q > limit:
                        stop = True
                        break
                    # early abandon: stop adding points once the partial total cannot win; first
                    # the centroids (sum_q |y_q - h_q|^2 >= Q |mean y - mean h|^2)
                    room = (min(best, limit) - q) / kq if kq > 0 else INF
                    d0 = ybar[j, 0] - h0
                    d1 = ybar[j, 1] - h1
                    d2 = ybar[j, 2] - h2
                    if nq * (d0 * d0 + d1 * d1 + d2 * d2) > room:
                        continue
                    acc = 0.0
                    for a in range(nq):
                        for b in range(3):
                            diff = ytab[j, a, b] - hbuf[0, a, b]
                            acc += diff * diff
                        if acc > room:
                            break
                    pairs += 1
                    if acc <= room:
                        tot = q + kq * acc
                        if tot < best:
                            best = tot
                            arg = j
                j0 += n_blk
            if arg < 0:
                continue
            val = dc + best
            if val + F[e] > ub:
                continue
            Q[e, c] = val
            back[e, c] = ps[arg]
            if val < colmin[e]:
                colmin[e] = val
    return pairs


# ----------------------------------------------------------------------------------- re-timing


PW_BLOCK = 128
"""NumPy's pairwise summation block (``PW_BLOCKSIZE`` of its ``pairwise_sum``)."""


@njit(cache=True, nogil=True)  # compiled with its caller (callers pass a run-time lo: one copy)
def _pairwise(a: np.ndarray, lo: int, n: int, tasks: np.ndarray, vals: np.ndarray) -> float:
    """``a[lo:lo + n].sum()`` in NumPy's order (its ``pairwise_sum``: eight partial sums up to
    :data:`PW_BLOCK` values, else the sums of two halves, the first a multiple of 8 long), so a
    reduction along a row equals NumPy's to the bit.

    Without recursion (a recursive function loaded from numba's cache crashed): the halves are
    walked depth first on the scratch stacks ``tasks (64, 3)`` (int64 ``lo, n, combine``) and
    ``vals (64,)``."""
    nt, nv = 1, 0
    tasks[0, 0], tasks[0, 1], tasks[0, 2] = lo, n, 0
    while nt > 0:
        nt -= 1
        lo_, n_, combine = tasks[nt, 0], tasks[nt, 1], tasks[nt, 2]
        if combine:
            nv -= 1
            vals[nv - 1] = vals[nv - 1] + vals[nv]
        elif n_ > PW_BLOCK:
            n2 = n_ // 2
            n2 -= n2 % 8
            tasks[nt, 0], tasks[nt, 1], tasks[nt, 2] = 0, 0, 1
            tasks[nt + 1, 0], tasks[nt + 1, 1], tasks[nt + 1, 2] = lo_ + n2, n_ - n2, 0
            tasks[nt + 2, 0], tasks[nt + 2, 1], tasks[nt + 2, 2] = lo_, n2, 0
            nt += 3
        elif n_ < 8:
            res = 0.0
            for i in range(n_):
                res += a[lo_ + i]
            vals[nv] = res
            nv += 1
        else:
            r0, r1, r2, r3 = a[lo_], a[lo_ + 1], a[lo_ + 2], a[lo_ + 3]
            r4, r5, r6, r7 = a[lo_ + 4], a[lo_ + 5], a[lo_ + 6], a[lo_ + 7]
            i = 8
            while i < n_ - (n_ % 8):
                r0 += a[lo_ + i]
                r1 += a[lo_ + i + 1]
                r2 += a[lo_ + i + 2]
                r3 += a[lo_ + i + 3]
                r4 += a[lo_ + i + 4]
                r5 += a[lo_ + i + 5]
                r6 += a[lo_ + i + 6]
                r7 += a[lo_ + i + 7]
                i += 8
            res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
            while i < n_:
                res += a[lo_ + i]
                i += 1
            vals[nv] = res
            nv += 1
    return float(vals[0])


@njit(cache=True, nogil=True)
def state_alignments(
    control: np.ndarray,
    seg_start: np.ndarray,
    seg_length: np.ndarray,
    bounds: np.ndarray,
    xp: np.ndarray,
    start: np.ndarray,
    dur: np.ndarray,
    context: int,
    scale: float,
    order: np.ndarray,
    out: np.ndarray,
) -> None:
    """The floor alignment of every re-timing state (:meth:`engines.control.dp._StateAlignments.of`,
    the operations of ``stretched_templates`` + ``paired_alignment`` in their order: equal to the bit).

    ``control (F, P, 3)``: the database's control cloud; per state ``(m,)``: ``seg_start``,
    ``seg_length`` its instance's first source frame and length (frames), ``bounds (m, 2)`` the
    instance's pair's first and last frame (source positions are clamped to them when ``context > 0``;
    ``(0, 2)``: no clamping), ``start`` its first input frame and ``dur`` its duration (full-rate
    frames); ``xp (T + 2 context, P, 3)`` the padded input; ``scale = P rate`` (the distance's unit:
    m²·s); ``order (m,)`` the states in an order where those of one template (instance and
    duration) follow each other: a template is sampled and centred once. Writes ``out (5, m)``:
    ``D``, ``cos``, ``sin``, ``tx``, ``tz``."""
    nf, npt = control.shape[0], control.shape[1]
    m = start.shape[0]
    top = max(nf - 2, 0)
    clamp = context > 0 and bounds.shape[0] == m
    n_max = 0
    for r in range(m):
        n_max = max(n_max, (dur[r] + 2 * context) * npt)
    wx = np.empty(n_max)
    wz = np.empty(n_max)
    wy = np.empty(n_max)
    ax = np.empty(n_max)
    az = np.empty(n_max)
    ay = np.empty(n_max)
    buf = np.empty(n_max)
    tasks = np.empty((64, 3), dtype=np.int64)
    vals = np.empty(64)
    zero = m - m  # a run-time 0 for _pairwise's lo: a literal would compile another copy
    max_, maz, sa = 0.0, 0.0, 0.0
    for j in range(m):
        r = order[j]
        d = dur[r]
        length = d + 2 * context
        n = length * npt
        fresh = j == 0
        if not fresh:
            r0 = order[j - 1]
            fresh = seg_start[r] != seg_start[r0] or seg_length[r] != seg_length[r0] or d != dur[r0]
            if clamp and not fresh:
                fresh = bounds[r, 0] != bounds[r0, 0] or bounds[r, 1] != bounds[r0, 1]
        if fresh:  # this state's stretched template, centred on the floor (shared by the next ones)
            s0 = float(seg_start[r])
            ln = float(seg_length[r])
            for f in range(length):
                pos = s0 + ln * (float(f - context) / d)
                if clamp:
                    pos = min(max(pos, float(bounds[r, 0])), float(bounds[r, 1]))
                fr = min(max(pos, 0.0), float(nf - 1))
                i0 = min(int(np.floor(fr)), top)
                i1 = min(i0 + 1, nf - 1)
                a = fr - i0
                b = 1 - a
                for q in range(npt):
                    k = f * npt + q
                    ax[k] = control[i0, q, 0] * b + control[i1, q, 0] * a
                    ay[k] = control[i0, q, 1] * b + control[i1, q, 1] * a
                    az[k] = control[i0, q, 2] * b + control[i1, q, 2] * a
            max_ = _pairwise(ax, zero, n, tasks, vals) / n
            maz = _pairwise(az, zero, n, tasks, vals) / n
            for k in range(n):
                ax[k] -= max_
                az[k] -= maz
            for k in range(n):
                buf[k] = ax[k] * ax[k] + az[k] * az[k]
            sa = _pairwise(buf, zero, n, tasks, vals)
        for f in range(length):
            w = start[r] + f
            for q in range(npt):
                k = f * npt + q
                wx[k] = xp[w, q, 0]
                wy[k] = xp[w, q, 1]
                wz[k] = xp[w, q, 2]
        mwx = _pairwise(wx, zero, n, tasks, vals) / n
        mwz = _pairwise(wz, zero, n, tasks, vals) / n
        for k in range(n):
            wx[k] -= mwx
            wz[k] -= mwz
        for k in range(n):
            buf[k] = ax[k] * wx[k] + az[k] * wz[k]
        c = _pairwise(buf, zero, n, tasks, vals)
        for k in range(n):
            buf[k] = az[k] * wx[k] - ax[k] * wz[k]
        s = _pairwise(buf, zero, n, tasks, vals)
        for k in range(n):
            buf[k] = wx[k] * wx[k] + wz[k] * wz[k]
        sw = _pairwise(buf, zero, n, tasks, vals)
        for k in range(n):
            e = wy[k] - ay[k]
            buf[k] = e * e
        sy = _pairwise(buf, zero, n, tasks, vals)
        rr = np.hypot(c, s)
        if rr > 0:
            cth, sth = c / rr, s / rr
        else:
            cth, sth = 1.0, 0.0
        res = sw + sa - 2 * rr + sy
        out[0, r] = (res if res >= 0.0 else 0.0) / scale
        out[1, r] = cth
        out[2, r] = sth
        out[3, r] = mwx - (cth * max_ + sth * maz)
        out[4, r] = mwz - (-sth * max_ + cth * maz)


@njit(cache=True, nogil=True)
def retime_chain(
    D: np.ndarray,
    offs: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    yn: np.ndarray,
    hn: np.ndarray,
    G: np.ndarray,
    g_offs: np.ndarray,
    kq: float,
    chosen: np.ndarray,
) -> float:
    """The re-timing DP over the segments' states (:func:`engines.control.dp._chain`, its operations
    in their order: equal to the bit). Returns the best score (``inf``: none) and writes the chosen
    state of every segment into ``chosen (L,)``.

    Per state ``(m,)``: ``D`` its distance, ``start``/``end`` its frames, ``yn``/``hn`` the squared
    norms of its placed tail and head points; ``offs (L + 1,)`` where each segment's states begin;
    ``G`` flat, for boundary ``i`` (from ``g_offs[i - 1]``) the ``(n_{i-1}, n_i)`` matrix ``2 Y H^T``
    of the placed tails of segment ``i - 1`` and heads of segment ``i``; ``kq = k / Q``."""
    n_seg = offs.shape[0] - 1
    m = D.shape[0]
    Q = np.empty(m)
    back = np.zeros(m, dtype=np.int64)
    for r in range(offs[0], offs[1]):
        Q[r] = D[r]
    for i in range(1, n_seg):
        p0, p1, c0, c1 = offs[i - 1], offs[i], offs[i], offs[i + 1]
        nc = c1 - c0
        g0 = g_offs[i - 1]
        for u in range(nc):
            cur = c0 + u
            best = INF
            arg = 0
            first = True
            for v in range(p1 - p0):
                prev = p0 + v
                if end[prev] != start[cur]:
                    tot = INF
                else:
                    cont = yn[prev] + hn[cur] - G[g0 + v * nc + u]
                    tot = Q[prev] + kq * (cont if cont >= 0.0 else 0.0)
                if first or tot < best:
                    best = tot
                    arg = v
                    first = False
            Q[cur] = best + D[cur]
            back[cur] = p0 + arg
    last = offs[n_seg - 1]
    score = Q[last]
    for r in range(offs[n_seg - 1] + 1, offs[n_seg]):
        if Q[r] < score:
            score = Q[r]
            last = r
    for i in range(n_seg - 1, -1, -1):
        chosen[i] = last
        last = back[last]
    return float(score)
