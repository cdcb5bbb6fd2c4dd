"""The forward pass of the segment DP (Hsu et al. 2004, Eq. 6-8) as one compiled kernel (numba).

Written by hand with numba rather than numpy: the pass is a sequence of small, data-dependent steps
per boundary (select the predecessors and successors a beam or a bound keeps, align their target
points, find each successor's best predecessor with an early exit), and in numpy their per-call
overhead dominated (about 15 ms per anytime stage on the salsa database). Compiled with
``cache=True``: the first call in a fresh environment compiles (a few seconds, see
``bench/control.py``'s ``first_call_s``), later processes load the machine code from
``__pycache__``.

Exactness: every successor ``i`` scans its predecessors in increasing score ``q_j``; since
continuity is never negative, once ``q_j`` reaches its best total so far (or what the upper bound
leaves for it), no later predecessor can win, so the scan stops there. The result is the optimum of
the candidates kept (all of them when neither beam nor caps are given).
"""

from __future__ import annotations

import numpy as np
from numba import njit

INF = np.inf


@njit(cache=True, nogil=True)
def _place(
    pts: np.ndarray,
    p: int,
    c: float,
    s: float,
    sum_x: float,
    sum_z: float,
    wx: float,
    wz: float,
    out: np.ndarray,
    o: int,
) -> None:
    """``out[o, q] = `` point ``pts[p, q]`` rotated about +Y by the alignment of cross terms ``(c, s)``
    and translated so the template's floor mean ``(sum_x, sum_z)`` lands on the window's ``(wx, wz)``."""
    r = np.hypot(c, s)
    if r > 0:
        cth, sth = c / r, s / r
    else:
        cth, sth = 1.0, 0.0
    tx = wx - (cth * sum_x + sth * sum_z)
    tz = wz - (cth * sum_z - sth * sum_x)
    for q in range(pts.shape[1]):
        x, y, z = pts[p, q, 0], pts[p, q, 1], pts[p, q, 2]
        out[o, q, 0] = cth * x + sth * z + tx
        out[o, q, 1] = y
        out[o, q, 2] = -sth * x + cth * z + tz


@njit(cache=True, nogil=True)
def _aligned(
    cell: int,
    end: int,
    pts: np.ndarray,
    p: int,
    C: np.ndarray,
    S: np.ndarray,
    sum_a: np.ndarray,
    n_pts: np.ndarray,
    dur: np.ndarray,
    context: int,
    cs: np.ndarray,
    rot: np.ndarray,
    trans: np.ndarray,
    rigid: bool,
    out: np.ndarray,
    o: int,
) -> None:
    """``out[o] = `` the target points ``pts[p] (Q, 3)`` of ``cell`` placed by its alignment ending at ``end``
    (:meth:`engines.control.dp.Interpretation.place`: the 3-D ``rot``, ``trans`` when ``rigid``)."""
    if rigid:
        for q in range(pts.shape[1]):
            for i in range(3):
                out[o, q, i] = (
                    rot[cell, end, i, 0] * pts[p, q, 0]
                    + rot[cell, end, i, 1] * pts[p, q, 1]
                    + rot[cell, end, i, 2] * pts[p, q, 2]
                    + trans[cell, end, i]
                )
        return
    lo = max(end - dur[cell], 0)
    inv = 1.0 / n_pts[cell]
    wx = (cs[end + 2 * context, 0] - cs[lo, 0]) * inv
    wz = (cs[end + 2 * context, 1] - cs[lo, 1]) * inv
    _place(pts, p, C[cell, end], S[cell, end], sum_a[cell, 0] * inv, sum_a[cell, 1] * inv, wx, wz, out, o)


@njit(cache=True, nogil=True)
def forward(
    D: np.ndarray,
    C: np.ndarray,
    S: np.ndarray,
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
    when none is kept) and ``back`` (its predecessor cell, -1 first) and return the pairs evaluated.

    ``D (C, T + 1)``, ``C``/``S`` cross terms, ``sum_a``, ``n_pts``, ``dur``, ``context``, ``cs``,
    ``rot``, ``trans``, ``rigid``: the interpretation (:class:`engines.control.dp.Interpretation`);
    ``tails``/``heads`` ``(N, Q, 3)``;
    ``kq`` the continuity weight per point; ``beam`` the width (``inf``: none); ``max_pred``,
    ``max_succ`` the caps per boundary (0: none); ``ub`` the upper bound (``inf``: none); ``F`` the
    admissible cost to go ``(T + 1,)``."""
    cells, t1 = D.shape
    t_len = t1 - 1
    nq = tails.shape[1]
    # end-time-major copy of D: a boundary's successors of one duration read one contiguous row
    DT = np.ascontiguousarray(D.T)
    colmin = np.full(t1, INF)
    for c in range(cells):
        d = dur[c]
        if d <= t_len and D[c, d] < INF:
            Q[d, c] = D[c, d]
            back[d, c] = -1
            if D[c, d] < colmin[d]:
                colmin[d] = D[c, d]
    pairs = 0
    pred = np.empty(cells, dtype=np.int64)
    pq = np.empty(cells)
    succ = np.empty(cells, dtype=np.int64)
    skey = np.empty(cells)
    ytab = np.empty((cells, nq, 3))
    hbuf = np.empty((1, nq, 3))
    ybar = np.empty((cells, 3))
    hbar = np.empty(3)
    for t in range(1, t_len):
        # predecessors: cells ending at t with a score within the bound and the beam
        qmin = INF
        for c in range(cells):
            if Q[t, c] < qmin:
                qmin = Q[t, c]
        if qmin == INF:
            continue
        npred = 0
        for c in range(cells):
            q = Q[t, c]
            if q < INF and q + F[t] <= ub and q <= qmin + beam:
                pred[npred] = c
                pq[npred] = q
                npred += 1
        if npred == 0:
            continue
        if max_pred > 0 and npred > max_pred:
            # the max_pred best by score (a selection, not a sort, of all of them)
            cut = np.partition(pq[:npred], max_pred - 1)[max_pred - 1]
            m = 0
            for j in range(npred):
                if pq[j] <= cut and m < max_pred:
                    pred[m] = pred[j]
                    pq[m] = pq[j]
                    m += 1
            npred = m
        order = np.argsort(pq[:npred], kind="mergesort")
        ps = pred[order]
        qs = pq[order]
        qkept = qs[0]
        # successors: cells starting at t that can still improve a score within the limits
        nsucc = 0
        for c in range(cells):
            e = t + dur[c]
            if e > t_len:
                continue
            dc = DT[e, c]
            if dc == INF:
                continue
            lower = qkept + dc
            if lower + F[e] > ub or lower > colmin[e] + beam:
                continue
            succ[nsucc] = c
            skey[nsucc] = dc + F[e]
            nsucc += 1
        if nsucc == 0:
            continue
        if max_succ > 0 and nsucc > max_succ:
            cut = np.partition(skey[:nsucc], max_succ - 1)[max_succ - 1]
            m = 0
            for i in range(nsucc):
                if skey[i] <= cut and m < max_succ:
                    succ[m] = succ[i]
                    m += 1
            nsucc = m
        ss = succ[:nsucc]
        for j in range(npred):
            c = ps[j]
            p = cell_inst[c]
            _aligned(c, t, tails, p, C, S, sum_a, n_pts, dur, context, cs, rot, trans, rigid, ytab, j)
        for j in range(npred):
            for b in range(3):
                ybar[j, b] = 0.0
                for a in range(nq):
                    ybar[j, b] += ytab[j, a, b] / nq
        for i in range(nsucc):
            c = ss[i]
            e = t + dur[c]
            p = cell_inst[c]
            _aligned(c, e, heads, p, C, S, sum_a, n_pts, dur, context, cs, rot, trans, rigid, hbuf, 0)
            dc = DT[e, c]
            hbar[:] = 0.0
            for a in range(nq):
                for b in range(3):
                    hbar[b] += hbuf[0, a, b] / nq
            limit = ub - dc - F[e]  # a total above the bound is pruned anyway
            best = INF
            arg = -1
            for j in range(npred):
                q = qs[j]
                if q >= best or q > limit:
                    break
                # early abandon: stop adding points once the partial total cannot win; first the
                # centroids (sum_q |y_q - h_q|^2 >= Q |mean y - mean h|^2), 3 numbers instead of 3 Q
                room = (min(best, limit) - q) / kq if kq > 0 else INF
                d0 = ybar[j, 0] - hbar[0]
                d1 = ybar[j, 1] - hbar[1]
                d2 = ybar[j, 2] - hbar[2]
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
