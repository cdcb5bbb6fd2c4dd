"""The full-rate re-timing (``engines.control.dp.retime``) against the NumPy implementation it
replaced (kept here as the reference): the same states, scores, boundaries and alignments, to the bit.

The reference is the code before the compiled state alignments and chain (per segment a grid of
boundary options, per duration one template sampling and alignment, per boundary the chain step)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

import engines.control.engine as control_engine
from engines.base import Run
from engines.control.dp import (
    Infeasible,
    Instances,
    Timed,
    legal_cells,
    pad_edges,
    paired_alignment,
    paired_procrustes,
    place_points,
    retime,
    stretched_templates,
)
from engines.control.kernels import _pairwise

Array = np.ndarray
DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


# ------------------------------------------------------------------- the reference (previous code)


def ref_states(
    t_len: int,
    inst: Instances,
    seq: Array,
    coarse_bounds: Array,
    rate: float,
    stretch_s: float | None,
    stretch_ratio: float | None,
    window: int,
    constraints: list[tuple[int, float]] | None,
) -> list[tuple[Array, Array]]:
    n_seg = seq.shape[0]
    cb = np.round(np.asarray(coarse_bounds, dtype=np.float64)).astype(np.intp)
    cb[0], cb[-1] = 0, t_len
    options = [np.array([0])]
    for i in range(1, n_seg):
        lo, hi = max(1, cb[i] - window), min(t_len - 1, cb[i] + window)
        options.append(np.arange(lo, hi + 1))
    options.append(np.array([t_len]))
    lengths_s = inst.length[seq] / inst.fps
    states = []
    for i in range(n_seg):
        a, b = np.meshgrid(options[i], options[i + 1], indexing="ij")
        a, b = a.ravel(), b.ravel()
        d = b - a
        ci, cd = legal_cells(lengths_s[i : i + 1], rate, stretch_s, stretch_ratio)
        ok = (d >= cd.min()) & (d <= cd.max())
        if not ok.any():
            ok = d == d[np.argmin(np.abs(d - (cb[i + 1] - cb[i])))]
        for seg_i, frame in constraints or []:
            if seg_i == i:
                ok &= (a <= frame) & (frame < b)
        states.append((a[ok], b[ok]))
    return states


def ref_alignments(
    x: Array,
    inst: Instances,
    state_inst: Array,
    start: Array,
    end: Array,
    rate: float,
    context: int,
    rigid: bool,
) -> dict[str, Any]:
    m = start.size
    al: dict[str, Any] = {
        "D": np.full(m, np.inf),
        "cos": np.ones(m),
        "sin": np.zeros(m),
        "tx": np.zeros(m),
        "tz": np.zeros(m),
        "rot": np.repeat(np.eye(3)[None], m, 0) if rigid else None,
        "trans": np.zeros((m, 3)) if rigid else None,
    }
    xp = pad_edges(x, context)
    p = x.shape[1]
    durs = end - start
    for d in np.unique(durs):
        rows = np.flatnonzero(durs == d)
        tmpl = stretched_templates(inst, state_inst[rows], int(d), rate, context)
        win = xp[start[rows, None] + np.arange(d + 2 * context)[None, :]]
        if rigid:
            res, r, t = paired_procrustes(win.reshape(rows.size, -1, 3), tmpl.reshape(rows.size, -1, 3))
            al["rot"][rows], al["trans"][rows] = r, t
            al["D"][rows] = res / (p * rate)
            continue
        res, c, s, tx_, tz_ = paired_alignment(win.reshape(rows.size, -1, 3), tmpl.reshape(rows.size, -1, 3))
        al["D"][rows], al["cos"][rows], al["sin"][rows] = res / (p * rate), c, s
        al["tx"][rows], al["tz"][rows] = tx_, tz_
    return al


def ref_place(al: dict[str, Any], points: Array, rows: Array) -> Array:
    rot, trans = al["rot"], al["trans"]
    return place_points(
        points,
        al["cos"][rows],
        al["sin"][rows],
        al["tx"][rows],
        al["tz"][rows],
        None if rot is None else rot[rows],
        None if trans is None else trans[rows],
    )


def ref_retime(
    x: Array,
    inst: Instances,
    seq: Array,
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
    n_seg = seq.shape[0]
    states = ref_states(
        x.shape[0], inst, seq, coarse_bounds, rate, stretch_s, stretch_ratio, window, constraints
    )
    flat_seg = np.concatenate([np.full(s[0].size, i) for i, s in enumerate(states)])
    start = np.concatenate([s[0] for s in states])
    end = np.concatenate([s[1] for s in states])
    al = ref_alignments(x, inst, seq[flat_seg], start, end, rate, context, rigid)
    offs = np.concatenate(([0], np.cumsum([s[0].size for s in states])))
    q_pts = inst.tails.shape[1]
    Q = al["D"][offs[0] : offs[1]].copy()
    backs = []
    for i in range(1, n_seg):
        prev = np.arange(offs[i - 1], offs[i])
        cur = np.arange(offs[i], offs[i + 1])
        if prev.size == 0 or cur.size == 0:
            raise Infeasible("re-timing found no legal boundaries")
        y = ref_place(al, inst.tails[seq[i - 1]][None].repeat(prev.size, 0), prev)
        h = ref_place(al, inst.heads[seq[i]][None].repeat(cur.size, 0), cur)
        y2, h2 = y.reshape(prev.size, -1), h.reshape(cur.size, -1)
        cont = (y2**2).sum(1)[:, None] + (h2**2).sum(1)[None] - 2 * y2 @ h2.T
        total = Q[:, None] + (k / q_pts) * np.maximum(cont, 0.0)
        total[end[prev][:, None] != start[cur][None, :]] = np.inf
        j = np.argmin(total, axis=0)
        Q = total[j, np.arange(cur.size)] + al["D"][cur]
        backs.append(j)
    if not np.isfinite(Q).any():
        raise Infeasible("re-timing found no legal boundaries")
    last = int(np.argmin(Q))
    score = float(Q[last])
    chosen = [offs[n_seg - 1] + last]
    for i in range(n_seg - 1, 0, -1):
        last = int(backs[i - 1][last])
        chosen.append(offs[i - 1] + last)
    idx = np.array(chosen[::-1], dtype=np.intp)
    bounds = np.concatenate((start[idx], end[idx[-1:]]))
    sel_rot = None if al["rot"] is None else al["rot"][idx]
    sel_trans = None if al["trans"] is None else al["trans"][idx]
    if sel_rot is not None and sel_trans is not None:
        fwd = sel_rot[:, :, 2]
        yaw = np.arctan2(fwd[:, 0], fwd[:, 2])
        al["cos"][idx], al["sin"][idx] = np.cos(yaw), np.sin(yaw)
        al["tx"][idx], al["tz"][idx] = sel_trans[:, 0], sel_trans[:, 2]
    y = ref_place(al, inst.tails[seq[:-1]], idx[:-1])
    h = ref_place(al, inst.heads[seq[1:]], idx[1:])
    C = ((y - h) ** 2).sum(axis=(1, 2)) / q_pts if n_seg > 1 else np.zeros(0)
    Dsel = al["D"][idx]
    return Timed(
        score,
        float(Dsel.sum()),
        float(k * C.sum()),
        seq.copy(),
        bounds,
        al["cos"][idx],
        al["sin"][idx],
        al["tx"][idx],
        al["tz"][idx],
        Dsel,
        C,
        sel_rot,
        sel_trans,
    )


# ------------------------------------------------------------------------------------------ checks

FIELDS = ("score", "interpretation", "continuity", "instances", "bounds", "cos", "sin", "tx", "tz", "D", "C")


def assert_same(got: Timed, want: Timed) -> None:
    """Every field equal to the bit (``array_equal``: no tolerance)."""
    for f in FIELDS:
        assert np.array_equal(np.asarray(getattr(got, f)), np.asarray(getattr(want, f))), f
    for f in ("rot", "trans"):
        g, w = getattr(got, f), getattr(want, f)
        assert (g is None) == (w is None), f
        if g is not None:
            assert np.array_equal(g, w), f


def random_problem(seed: int, points: int = 3) -> dict[str, Any]:
    """A random database (instances of 8-30 frames at 30 fps, some paired with pair bounds) and an
    input made of some of them stretched, with noise, and coarse boundaries off by a few frames."""
    rng = np.random.default_rng(seed)
    n_inst = int(rng.integers(4, 12))
    lengths = rng.integers(8, 31, size=n_inst)
    frames = int(lengths.sum()) + 1
    cloud = np.cumsum(rng.normal(scale=0.05, size=(frames, points, 3)), axis=0)
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1])).astype(np.intp)
    target = cloud + rng.normal(scale=0.1, size=cloud.shape)
    pair_end = np.full(n_inst, frames - 1)
    pair_bounds = np.stack((np.zeros(n_inst, dtype=np.intp), pair_end), 1).astype(np.intp)
    inst = Instances(
        30.0,
        starts,
        lengths.astype(np.intp),
        cloud,
        target[starts + lengths],
        target[starts],
        pair_bounds if rng.random() < 0.5 else None,
    )
    n_seg = int(rng.integers(1, 9))
    seq = rng.integers(0, n_inst, size=n_seg).astype(np.intp)
    durs = np.maximum(2, np.round(lengths[seq] * rng.uniform(0.8, 1.25, size=n_seg))).astype(np.intp)
    t_len = int(durs.sum())
    x = np.cumsum(rng.normal(scale=0.05, size=(t_len, points, 3)), axis=0)
    bounds = np.concatenate(([0], np.cumsum(durs))).astype(np.float64)
    coarse = bounds + rng.uniform(-3, 3, size=bounds.size)
    return {"x": x, "inst": inst, "seq": seq, "coarse": coarse, "rng": rng}


@pytest.mark.parametrize("seed", range(40))
def test_retime_equals_the_numpy_reference_on_random_problems(seed: int) -> None:
    pb = random_problem(seed)
    rng = pb["rng"]
    stretch_s, stretch_ratio = (0.15, None) if seed % 3 else (None, 0.2)
    window = int(rng.integers(1, 5))
    context = int(rng.integers(0, 4)) if seed % 2 else 0
    k = float(rng.uniform(0.0, 2.0))
    constraints: list[tuple[int, float]] = []
    if seed % 5 == 0 and pb["seq"].size > 1:  # a segment must keep covering its coarse middle
        i = int(rng.integers(0, pb["seq"].size))
        constraints.append((i, int((pb["coarse"][i] + pb["coarse"][i + 1]) / 2)))
    args = (
        pb["x"],
        pb["inst"],
        pb["seq"],
        pb["coarse"],
        k,
        30.0,
        stretch_s,
        stretch_ratio,
        window,
        constraints,
    )
    for rigid in (False, True) if seed < 10 else (False,):
        try:
            want = ref_retime(*args, context=context, rigid=rigid)
        except Infeasible:
            with pytest.raises(Infeasible):
                retime(*args, context=context, rigid=rigid)
            continue
        assert_same(retime(*args, context=context, rigid=rigid), want)


def test_retime_keeps_the_coarse_duration_when_none_is_legal() -> None:
    """No stretch at all and coarse boundaries far off: a segment with no legal duration within the
    window keeps the duration of the option nearest the coarse one (the fallback), as the reference."""
    fallbacks = 0
    for seed in range(12):
        pb = random_problem(seed)
        seq, coarse = pb["seq"], pb["coarse"].copy()
        if seq.size < 2:
            continue
        coarse[1:-1] += 6.0 * (-1.0) ** np.arange(coarse.size - 2)  # durations off by about 12 frames
        coarse[1:-1] = np.clip(coarse[1:-1], 2, pb["x"].shape[0] - 2)
        args = (pb["x"], pb["inst"], seq, coarse, 1.0, 30.0, 0.0, None, 1)
        states = ref_states(pb["x"].shape[0], pb["inst"], seq, coarse, 30.0, 0.0, None, 1, None)
        if any((b <= a).any() for a, b in states):
            continue  # an empty or reversed window: the reference's mean of nothing (NaN)
        try:
            want = ref_retime(*args)
        except Infeasible:
            with pytest.raises(Infeasible):
                retime(*args)
            continue
        assert_same(retime(*args), want)
        fallbacks += int((np.diff(want.bounds) != pb["inst"].length[seq]).any())
    assert fallbacks > 0


def test_retime_without_boundary_options_is_infeasible() -> None:
    """A coarse boundary past the input's end leaves a segment no option: Infeasible (the reference
    failed there with NumPy's ValueError of an empty argmin)."""
    pb = random_problem(3)
    coarse = pb["coarse"] * 1.3
    args = (pb["x"], pb["inst"], pb["seq"], coarse, 1.0, 30.0, 0.0, None, 1)
    with pytest.raises(ValueError, match="empty sequence"):
        ref_retime(*args)
    with pytest.raises(Infeasible):
        retime(*args)


def test_pairwise_sum_is_numpys() -> None:
    """The compiled sum (eight partial sums, halves above 128 values) equals NumPy's row sums."""
    rng = np.random.default_rng(0)
    tasks, vals = np.empty((64, 3), dtype=np.int64), np.empty(64)
    for n in [*range(1, 300), 511, 1000, 4099]:
        rows = rng.normal(size=(2, n, 3)) * 10.0 ** rng.uniform(-4, 4, size=(2, n, 3))
        col = rows[..., 1]  # a strided view, as the reference's reductions see it
        want = col.sum(1)
        for r in range(2):
            assert _pairwise(np.ascontiguousarray(col[r]), 0, n, tasks, vals) == want[r]
        # an offset into a longer buffer
        buf = np.concatenate((rng.normal(size=5), col[0]))
        assert _pairwise(buf, 5, n, tasks, vals) == want[0]


@pytest.mark.skipif(not (DATA / "cmu-salsa").exists(), reason="no shared salsa data")
@pytest.mark.parametrize("held", ["07", "10"])
def test_retime_equals_the_reference_on_salsa(held: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every re-timing of a search on a held-out salsa dance (floor and rigid alignment) equals the
    reference's, to the bit."""
    from engines.base import CollectingEmitter
    from tests.engines.test_control_data import engine_of

    s = DATA / "cmu-salsa"
    trials = sorted({f.name[3:5] for f in s.glob("60_*_scaled.bvh")})
    pairs = [
        ((s / f"60_{t}_scaled.bvh").read_bytes(), (s / f"61_{t}_scaled.bvh").read_bytes())
        for t in trials
        if t != held
    ]
    engine = engine_of(pairs, {"method": "beats", "beats_per_segment": 2})
    calls: list[bool] = []

    def checked(*args: Any, **kw: Any) -> Timed:
        got = retime(*args, **kw)
        assert_same(got, ref_retime(*args, **kw))
        calls.append(bool(kw.get("rigid", False)))
        return got

    monkeypatch.setattr(control_engine, "retime", checked)
    from engines.registry import parse_job_request

    lead = (s / f"60_{held}_scaled.bvh").read_bytes()
    for extra in ({}, {"alignment": "rigid"}):
        request = parse_job_request({"engine": "control", "control": {"bvh": "lead.bvh"}, **extra})
        request.attach_inputs({"lead.bvh": lead})
        engine.search(request, Run(60.0, emit=CollectingEmitter()))
    assert False in calls and True in calls
