"""The control DP's compiled parts (engines/control/kernels.py) against plain references: the cost to
go, the exact search with its screens on problems with many predecessors per boundary, the selection
for the beam caps, the template sampling and the time-major interpretation."""

from __future__ import annotations

import numpy as np
import pytest

from engines.control.dp import (
    Instances,
    Interpretation,
    cost_to_go,
    interpretation,
    legal_cells,
    paired_alignment,
    solve,
    stretched_templates,
)
from engines.control.kernels import BLOCK, _kth, sample_frames
from engines.control.points import sample_cloud

RATE = 10.0


def smooth_walk(frames: int, points: int, seed: int) -> np.ndarray:
    """A smooth random cloud ``(F, P, 3)``."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(scale=0.2, size=(frames, points, 3)), axis=0)
    kernel = np.ones(3) / 3
    return np.apply_along_axis(lambda v: np.convolve(v, kernel, mode="same"), 0, walk)


def many_instances(seed: int, count: int = 40, frames: int = 16) -> tuple[Instances, np.ndarray]:
    """``count`` instances of 2-4 frames cut from one cloud, and an input of ``frames`` frames: some
    boundaries keep more than :data:`BLOCK` predecessors, so the block screen runs over several blocks."""
    rng = np.random.default_rng(seed)
    lengths = rng.integers(2, 5, size=count)
    cloud = smooth_walk(int(lengths.sum()) + 1, 3, seed)
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1])).astype(np.intp)
    inst = Instances(
        fps=RATE,
        start=starts,
        length=lengths.astype(np.intp),
        control=cloud,
        tails=cloud[starts + lengths],
        heads=cloud[starts],
    )
    x = smooth_walk(frames, 3, seed + 100) + rng.normal(size=3)
    return inst, x


def reference_dp(interp: Interpretation, inst: Instances, ci: np.ndarray, cd: np.ndarray, k: float) -> float:
    """Eq. 6-8 with every predecessor of every cell at every end time (no pruning, NumPy)."""
    D = interp.D
    cells, t1 = D.shape
    kq = k / inst.tails.shape[1]
    Q = np.full((t1, cells), np.inf)
    for e in range(1, t1):
        for c in range(cells):
            t = e - int(cd[c])
            if t < 0 or not np.isfinite(D[c, e]):
                continue
            if t == 0:
                Q[e, c] = D[c, e]
                continue
            preds = np.flatnonzero(np.isfinite(Q[t]))
            if preds.size == 0:
                continue
            y = interp.place(inst.tails[ci[preds]], preds, np.full(preds.size, t))
            h = interp.place(inst.heads[ci[c : c + 1]], np.array([c]), np.array([e]))
            cont = kq * ((y - h) ** 2).sum(axis=(1, 2))
            Q[e, c] = D[c, e] + float(np.min(Q[t, preds] + cont))
    return float(Q[-1].min())


def reference_cost_to_go(D: np.ndarray, cell_dur: np.ndarray) -> np.ndarray:
    """The best tiling of ``[t, T)`` by ``D`` alone, by a loop over start times."""
    t_len = D.shape[1] - 1
    durs = np.unique(cell_dur)
    best_d = np.stack([D[cell_dur == d].min(axis=0) for d in durs])
    F = np.full(t_len + 1, np.inf)
    F[t_len] = 0.0
    for t in range(t_len - 1, -1, -1):
        ends = t + durs
        ok = ends <= t_len
        if ok.any():
            F[t] = np.min(best_d[ok, ends[ok]] + F[ends[ok]])
    return F


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_exact_equals_a_search_without_pruning(seed: int) -> None:
    inst, x = many_instances(seed)
    ci, cd = legal_cells(inst.length / inst.fps, RATE, 0.1, None)
    interp = interpretation(x, inst, ci, cd, RATE)
    k = 5.0  # continuity matters: the best predecessor is seldom the one of lowest score
    reference = reference_dp(interp, inst, ci, cd, k)
    exhaustive = solve(interp, inst, ci, cd, k)
    assert exhaustive.score == pytest.approx(reference, rel=1e-12)
    # predecessors at some boundary span several screened blocks
    ends = np.flatnonzero(np.isfinite(interp.DT).sum(axis=1) > 2 * BLOCK)
    assert ends.size > 0
    to_go = cost_to_go(interp.D, cd)
    narrow = solve(interp, inst, ci, cd, k, beam=1e-3, max_cells=(2, 4), to_go=to_go)
    assert narrow.score >= exhaustive.score - 1e-12
    bnb = solve(interp, inst, ci, cd, k, upper_bound=narrow.score, to_go=to_go)
    assert bnb.score == pytest.approx(exhaustive.score, rel=1e-12)
    assert list(bnb.cells) == list(exhaustive.cells)
    assert bnb.expanded <= exhaustive.expanded


@pytest.mark.parametrize("seed", [0, 3])
def test_cost_to_go_is_the_reference_and_admissible(seed: int) -> None:
    inst, x = many_instances(seed)
    ci, cd = legal_cells(inst.length / inst.fps, RATE, 0.1, None)
    interp = interpretation(x, inst, ci, cd, RATE)
    interp.D[5, :] = np.inf  # an illegal cell changes nothing
    F = cost_to_go(interp.D, cd)
    assert np.array_equal(F, reference_cost_to_go(interp.D, cd))
    # admissible: never above the cost still to come on the optimum's own tiling
    res = solve(interp, inst, ci, cd, 0.5)
    starts = res.ends - cd[res.cells]
    for i, t in enumerate(starts):
        rest = interp.D[res.cells[i:], res.ends[i:]].sum()
        assert F[t] <= rest + 1e-12
    with pytest.raises(ValueError, match="sorted by duration"):
        cost_to_go(interp.D, cd[::-1].copy())


def test_solve_reuses_its_tables_between_problems() -> None:
    inst, x = many_instances(4)
    ci, cd = legal_cells(inst.length / inst.fps, RATE, 0.1, None)
    a = interpretation(x, inst, ci, cd, RATE)
    b = interpretation(x[:11], inst, ci, cd, RATE)
    first = solve(a, inst, ci, cd, 0.5)
    other = solve(b, inst, ci, cd, 0.5)
    again = solve(a, inst, ci, cd, 0.5)
    assert again.score == first.score and list(again.cells) == list(first.cells)
    assert other.ends[-1] == 11


def test_kth_is_the_partition() -> None:
    rng = np.random.default_rng(0)
    work = np.empty(6000)
    for n, k in [(1370, 127), (300, 15), (5000, 255), (86, 15), (256, 63), (1000, 999), (1, 0)]:
        for rep in range(12):
            v = rng.normal(size=n) if rep % 2 else np.round(rng.normal(size=n), 1)  # ties
            if rep % 3 == 0:
                v[rng.integers(0, n, max(1, n // 20))] = np.inf
            if rep == 4:
                v[:] = 1.0
            assert _kth(v, n, k, work) == np.partition(v, k)[k]


def test_sample_frames_is_sample_cloud_to_the_bit() -> None:
    rng = np.random.default_rng(1)
    cloud = rng.normal(size=(50, 4, 3))
    for _ in range(10):
        pos = rng.uniform(-3.0, 55.0, size=(7, 9))
        pos[0, :3] = [0.0, 49.0, 48.0]
        assert np.array_equal(sample_frames(cloud, pos), sample_cloud(cloud, pos))
    single = rng.normal(size=(1, 4, 3))
    pos = rng.uniform(-1.0, 2.0, size=(3, 4))
    assert np.array_equal(sample_frames(single, pos), sample_cloud(single, pos))


@pytest.mark.parametrize("context", [0, 2])
def test_interpretation_matches_window_by_window_alignment(context: int) -> None:
    inst, x = many_instances(5)
    ci, cd = legal_cells(inst.length / inst.fps, RATE, 0.1, None)
    interp = interpretation(x, inst, ci, cd, RATE, context)
    assert interp.DT.flags.c_contiguous and interp.D.shape == (ci.size, x.shape[0] + 1)
    xp = np.concatenate((np.repeat(x[:1], context, 0), x, np.repeat(x[-1:], context, 0)))
    p = x.shape[1]
    for c in range(0, ci.size, 7):
        d = int(cd[c])
        assert np.isinf(interp.D[c, :d]).all()
        tmpl = stretched_templates(inst, ci[c : c + 1], d, RATE, context).reshape(1, -1, 3)
        for e in range(d, x.shape[0] + 1):
            win = xp[e - d : e + context * 2].reshape(1, -1, 3)
            res, cos, sin, _, _ = paired_alignment(win, tmpl)
            assert interp.D[c, e] == pytest.approx(res[0] / (p * RATE), abs=1e-9)
            al = interp.alignment(np.array([c]), np.array([e]))
            assert al[0, 0] == pytest.approx(cos[0], abs=1e-9) and al[1, 0] == pytest.approx(sin[0], abs=1e-9)


@pytest.mark.parametrize("n", [0, 1, 2, 7, 64, 301])
def test_stable_argsort_matches_numpy(n: int) -> None:
    from engines.control.kernels import _argsort_stable

    rng = np.random.default_rng(n)
    keys = np.concatenate((np.round(rng.normal(size=n), 1), [np.inf] * 3))  # many ties, and inf
    order, tmp = np.full(n + 3, -1, dtype=np.int64), np.empty(n + 3, dtype=np.int64)
    _argsort_stable(keys, n, order, tmp)
    np.testing.assert_array_equal(order[:n], np.argsort(keys[:n], kind="stable"))
    keys[: n // 2] = np.inf
    _argsort_stable(keys, n + 3, order, tmp)
    np.testing.assert_array_equal(order, np.argsort(keys, kind="stable"))
