"""The control-by-example engine (Hsu, Gentry & Popović 2004): DP, beam, constraints, schemas, paths."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from pydantic import ValidationError

from engines.base import EngineError, Run
from engines.control.build import cluster_instances, instances_from_boundaries
from engines.control.dp import (
    Infeasible,
    Instances,
    align_points,
    apply_constraints,
    cost_to_go,
    interpretation,
    legal_cells,
    paired_procrustes,
    retime,
    solve,
)
from engines.control.engine import ControlEngine
from engines.control.points import trajectory_control
from engines.library import ClipInput, build_library, library_to_arrays
from engines.registry import parse_database_spec, parse_job_request
from motion.bvh import bvh_text
from motion.ground import ground_frames
from tests.engines.emitters import Collect
from tests.motion.synthetic import walking_biped

RATE = 10.0


def random_database(frames: int = 120, points: int = 3, seed: int = 0) -> np.ndarray:
    """A smooth random control cloud ``(F, P, 3)`` (a random walk, smoothed)."""
    rng = np.random.default_rng(seed)
    steps = rng.normal(scale=0.2, size=(frames, points, 3))
    walk = np.cumsum(steps, axis=0)
    kernel = np.ones(3) / 3
    return np.apply_along_axis(lambda v: np.convolve(v, kernel, mode="same"), 0, walk)


def instances_of(cloud: np.ndarray, lengths: list[int], target: np.ndarray | None = None) -> Instances:
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1])).astype(np.intp)
    length = np.asarray(lengths, dtype=np.intp)
    tgt = cloud if target is None else target
    return Instances(
        fps=RATE,
        start=starts,
        length=length,
        control=cloud,
        tails=tgt[starts + length],
        heads=tgt[starts],
    )


def rigid(cloud: np.ndarray, theta: float, tx: float, tz: float) -> np.ndarray:
    n = cloud.shape[0]
    return align_points(
        cloud, np.full(n, np.cos(theta)), np.full(n, np.sin(theta)), np.full(n, tx), np.full(n, tz)
    )


def dp_setup(inst: Instances, x: np.ndarray, stretch: float = 0.0):  # type: ignore[no-untyped-def]
    ci, cd = legal_cells(inst.length / inst.fps, RATE, stretch, None)
    return ci, cd, interpretation(x, inst, ci, cd, RATE)


def test_dp_recovers_a_copied_sequence_under_a_rigid_move() -> None:
    cloud = random_database(130)
    lengths = [6, 8, 7, 5, 9, 6, 8, 7, 6, 8, 7, 6, 8, 7, 6]
    inst = instances_of(cloud, lengths)
    order = [3, 11, 0, 7, 5]
    x = np.concatenate([cloud[inst.start[s] : inst.start[s] + inst.length[s]] for s in order])
    x = rigid(x, 0.6, 2.0, -1.0)
    ci, cd, interp = dp_setup(inst, x, stretch=0.1)
    res = solve(interp, inst, ci, cd, k=0.0)
    assert list(ci[res.cells]) == order
    assert res.score == pytest.approx(0.0, abs=1e-9)
    # the alignment found is the move applied
    last = res.cells[-1], res.ends[-1]
    assert np.degrees(np.arctan2(interp.sin[last], interp.cos[last])) == pytest.approx(np.degrees(0.6))


def test_contiguous_source_costs_nothing_with_continuity() -> None:
    cloud = random_database(100, seed=3)
    inst = instances_of(cloud, [7] * 14)
    x = rigid(cloud[14:56].copy(), -1.1, 0.5, 0.3)  # instances 2..7, played on
    ci, cd, interp = dp_setup(inst, x, stretch=0.1)
    res = solve(interp, inst, ci, cd, k=5.0)
    assert list(ci[res.cells]) == [2, 3, 4, 5, 6, 7]
    assert res.score == pytest.approx(0.0, abs=1e-9) and res.continuity == pytest.approx(0.0, abs=1e-9)


def brute_force(interp, inst, ci, cd, k: float) -> float:  # type: ignore[no-untyped-def]
    """The optimum of Eq. 5 by enumerating every sequence of cells tiling the input."""
    t_len = interp.D.shape[1] - 1
    q = inst.tails.shape[1]
    best = np.inf

    cells, t1 = interp.D.shape
    cc = np.repeat(np.arange(cells), t1)
    tt = np.tile(np.arange(t1), cells)

    def aligned(points: np.ndarray) -> np.ndarray:
        out = align_points(
            points[ci[cc]], interp.cos[cc, tt], interp.sin[cc, tt], interp.tx[cc, tt], interp.tz[cc, tt]
        )
        return out.reshape(cells, t1, -1)

    tails, heads = aligned(inst.tails), aligned(inst.heads)

    def rec(t: int, prev: tuple[int, int] | None, acc: float) -> None:
        nonlocal best
        if t == t_len:
            best = min(best, acc)
            return
        for c in range(ci.size):
            end = t + int(cd[c])
            if end > t_len or not np.isfinite(interp.D[c, end]):
                continue
            cost = acc + interp.D[c, end]
            if prev is not None:
                gap = tails[prev[0], prev[1]] - heads[c, end]
                cost += k * float((gap**2).sum()) / q
            rec(end, (c, end), cost)

    rec(0, None, 0.0)
    return best


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dp_is_optimal_and_beam_and_exact_agree(seed: int) -> None:
    rng = np.random.default_rng(seed)
    cloud = random_database(60, seed=seed)
    inst = instances_of(cloud, [2, 3, 2, 3])
    x = random_database(9, seed=seed + 10) + rng.normal(size=3)
    ci, cd, interp = dp_setup(inst, x, stretch=0.1)  # durations 1-4
    k = 0.7
    exhaustive = solve(interp, inst, ci, cd, k)
    assert exhaustive.score == pytest.approx(brute_force(interp, inst, ci, cd, k), rel=1e-9)
    wide = solve(interp, inst, ci, cd, k, beam=1e9)
    assert wide.score == pytest.approx(exhaustive.score, rel=1e-12)
    narrow = solve(interp, inst, ci, cd, k, beam=1e-3)
    assert narrow.score >= exhaustive.score - 1e-12
    bnb = solve(interp, inst, ci, cd, k, upper_bound=narrow.score, to_go=cost_to_go(interp.D, cd))
    assert bnb.score == pytest.approx(exhaustive.score, rel=1e-12)
    assert bnb.expanded <= exhaustive.expanded


def test_stretch_bounds() -> None:
    lengths_s = np.array([0.6, 1.0, 0.25])
    ci, cd = legal_cells(lengths_s, 10.0, 0.15, None)
    for s, d in zip(ci, cd, strict=True):
        assert abs(d / 10.0 - lengths_s[s]) <= 0.15 + 1e-9
    assert set(cd[ci == 0]) == {5, 6, 7} and set(cd[ci == 2]) == {1, 2, 3, 4}
    assert np.all(np.diff(cd) >= 0)
    ci, cd = legal_cells(lengths_s, 10.0, None, 0.2)
    assert set(cd[ci == 1]) == {8, 9, 10, 11, 12}
    ci, cd = legal_cells(np.array([0.62]), 10.0, 0.0, None)  # no stretch: the nearest duration only
    assert cd.tolist() == [6]


def test_hard_constraint_is_honoured() -> None:
    cloud = random_database(100, seed=5)
    inst = instances_of(cloud, [6] * 16)
    x = cloud[12:48].copy()  # instances 2..7 fit exactly
    ci, cd, interp = dp_setup(inst, x, stretch=0.1)
    apply_constraints(interp.D, ci, cd, [(10, 20)])  # instance 10 must cover frame 20
    res = solve(interp, inst, ci, cd, k=1.0)
    starts = res.ends - cd[res.cells]
    covering = (starts <= 20) & (res.ends > 20)
    assert ci[res.cells][covering].tolist() == [10]
    assert res.score > 0  # the constraint costs something
    apply_constraints(interp.D, ci, cd, [(11, 20)])  # two instances at one frame: impossible
    with pytest.raises(Infeasible):
        solve(interp, inst, ci, cd, k=1.0)


def test_retime_recovers_full_rate_boundaries() -> None:
    cloud = random_database(200, seed=7)
    lengths = [16, 19, 17, 21, 18, 16, 20, 17, 19, 18]
    inst = instances_of(cloud, lengths)
    inst.fps = 30.0
    order = np.array([4, 1, 8, 2])
    x = np.concatenate([cloud[inst.start[s] : inst.start[s] + inst.length[s]] for s in order])
    truth = np.concatenate(([0], np.cumsum(inst.length[order])))
    coarse = truth + np.array([0, 2, -3, 1, 0])  # a coarse solution's boundaries, off by a few frames
    timed = retime(x, inst, order, coarse, 0.5, 30.0, 0.2, None, window=3)
    assert timed.bounds.tolist() == truth.tolist()
    assert timed.interpretation == pytest.approx(0.0, abs=1e-9)
    assert timed.score == pytest.approx(timed.interpretation + timed.continuity)


def test_clustering_keeps_one_of_near_duplicates() -> None:
    cloud = random_database(40, seed=2)
    segs = np.stack([cloud[0:8], cloud[0:8] + 0.001, cloud[20:28]])
    segs[1] = rigid(segs[1], 1.0, 3.0, 1.0)  # a moved copy is the same instance (Eq. 1 aligns)
    rep = cluster_instances(segs, 0.05, seed=0)
    assert rep[0] == rep[1] and rep[2] == 2 and rep[0] in (0, 1)
    assert cluster_instances(segs, 0.0, seed=0).tolist() == [0, 1, 2]


def test_segments_from_boundaries() -> None:
    b = np.array([0, 10, 20, 31, 40, 50])
    rows = instances_from_boundaries(b, 2, 60, 30.0, 0.2, 4.0, overlap=False)
    assert rows.tolist() == [[0, 20], [20, 20]]
    rows = instances_from_boundaries(b, 2, 60, 30.0, 0.2, 4.0, overlap=True)
    assert rows[:, 0].tolist() == [0, 10, 20, 31]


def test_impossible_speed_names_the_segment() -> None:
    t = np.arange(60) / 30.0
    pts = np.stack((np.where(t < 1.0, 1.2 * t, 1.2 + 12.0 * (t - 1.0)), np.zeros_like(t)), axis=-1)
    with pytest.raises(EngineError, match=r"too fast between t = 1\.\d+ s .* m/s"):
        trajectory_control(pts, 30.0, 0.2)
    cloud, path = trajectory_control(pts[:30], 30.0, 0.2, temporal_s=0.1)
    assert cloud.shape == (30, 2, 3)
    sep = np.linalg.norm(cloud[:, 0] - cloud[:, 1], axis=-1)
    assert np.allclose(sep, 0.2)
    # walking along +X: the left point is on the -Z side (facing +X, the left is -Z)
    assert np.all(cloud[5:25, 0, 2] < cloud[5:25, 1, 2])


def test_schema_pairs_become_clips_and_errors_are_clear() -> None:
    spec = parse_database_spec(
        {
            "kind": "control",
            "pairs": [
                {"control": "d/60_01.bvh", "target": "61_01.bvh"},
                {"target": {"bvh": "w.bvh", "units": "cm"}},
            ],
            "segmentation": {"method": "beats", "beats_per_segment": 2},
        }
    )
    assert [c.display_name() for c in spec.clips] == ["61_01", "60_01", "w"]
    assert spec.pairs[0].control == "60_01" and spec.pairs[1].control is None
    again = parse_database_spec(spec.model_dump(mode="json"))  # stored specs re-validate unchanged
    assert again == spec
    bad = [
        ({"kind": "control", "pairs": [{"control": "a.bvh"}]}, "target"),
        ({"kind": "control", "pairs": [{"control": "a.bvh", "target": "a.bvh"}]}, "same clip"),
        (
            {"kind": "control", "pairs": [{"target": "a.bvh"}], "segmentation": {"method": "markers"}},
            "markers",
        ),
        ({"kind": "control", "pairs": [{"target": "a.bvh", "markers_s": [1.0, 0.5]}]}, "increasing"),
        ({"kind": "control", "pairs": []}, "at least 1"),
        ({"kind": "control", "pairs": [{"target": "a.bvh"}], "segmentation": {"method": "x"}}, "method"),
    ]
    for data, words in bad:
        with pytest.raises(ValidationError, match=words):
            parse_database_spec(data)
    req = parse_job_request({"engine": "control", "control": {"bvh": "lead.bvh"}})
    assert req.input_files() == ["lead.bvh"]
    traj = parse_job_request(
        {"engine": "control", "control": {"trajectory": {"fps": 30, "points": [[0, 0], [0, 1]]}}}
    )
    assert traj.input_files() == []
    for data, words in [
        ({"control": {}}, "exactly one"),
        ({"control": {"bvh": "a", "trajectory": {"fps": 30, "points": [[0, 0], [1, 1]]}}}, "exactly one"),
        ({"control": {"bvh": "a"}, "stretch_s": 0.1, "stretch_ratio": 0.1}, "at most one"),
        ({"control": {"bvh": "a"}, "constraints": [{"time_s": 1.0}]}, "instance"),
    ]:
        with pytest.raises(ValidationError, match=words):
            parse_job_request({"engine": "control", **data})


# ------------------------------------------------------------------------- end to end (synthetic)


def walk_engine() -> ControlEngine:
    clips = [
        ClipInput(
            f"walk{i}",
            bvh_text(walking_biped(240, speed=1.0 + 0.2 * i, heading_deg=40.0 * i, seed=i)).encode(),
        )
        for i in range(3)
    ]
    spec = parse_database_spec(
        {
            "kind": "control",
            "pairs": [{"target": c.name} for c in clips],
            "clips": [{"bvh": f"{c.name}.bvh", "name": c.name} for c in clips],
            "segmentation": {"method": "fixed", "seconds": 0.5},
        }
    )
    library = build_library(clips, spec.fps)
    arrays = ControlEngine.build(spec, library, Collect(), lambda: False)
    arrays.update(library_to_arrays(library))
    return ControlEngine(library, arrays)


def test_walk_from_a_path_follows_it() -> None:
    engine = walk_engine()
    held = walking_biped(150, speed=1.1, heading_deg=-30.0, seed=9)
    path, _ = ground_frames(held)
    req = parse_job_request(
        {"engine": "control", "control": {"trajectory": {"fps": 30, "points": path.tolist()}}, "budget_s": 5}
    )
    out = Collect()
    engine.search(req, Run(5.0, emit=out))
    assert out.solutions and all(b.score < a.score for a, b in itertools.pairwise(out.solutions))
    sol = out.solutions[-1]
    assert sol.motion.num_frames == 150 and sol.motion.fps == 30.0
    got, _ = ground_frames(sol.motion)
    rms = float(np.sqrt(((got - path) ** 2).sum(-1).mean()))
    assert rms < 0.05 * 1.7
    assert len(sol.provenance) == 150 and sol.annotations["segments"]
    assert len(sol.annotations["foot_contacts"]["flags"][0]) == 150
    # a trajectory cannot drive a dance database, a BVH is needed: clear error the other way round
    fast = parse_job_request(
        {"engine": "control", "control": {"trajectory": {"fps": 30, "points": (path * 8).tolist()}}}
    )
    with pytest.raises(EngineError, match="too fast"):
        engine.search(fast, Run(5.0, emit=Collect()))
    # a control shorter than any segment cannot be interpreted
    short = parse_job_request(
        {"engine": "control", "control": {"trajectory": {"fps": 30, "points": path[:5].tolist()}}}
    )
    with pytest.raises(EngineError, match="cannot be tiled"):
        engine.search(short, Run(5.0, emit=Collect()))


def test_context_and_velocity_continuity_options() -> None:
    cloud = random_database(100, seed=3)
    inst = instances_of(cloud, [7] * 14)
    x = rigid(cloud[14:56].copy(), -1.1, 0.5, 0.3)
    ci, cd = legal_cells(inst.length / inst.fps, RATE, 0.1, None)
    interp = interpretation(x, inst, ci, cd, RATE, context=2)  # the motion around each segment counts
    res = solve(interp, inst, ci, cd, k=5.0)
    assert list(ci[res.cells]) == [2, 3, 4, 5, 6, 7]
    engine = walk_engine()
    three = engine.instances_for(0.2)
    assert three.tails.shape[1] == 3 * engine.solver_instances_.tails.shape[1]
    assert np.allclose(
        three.tails[:, : engine.solver_instances_.tails.shape[1]], engine.solver_instances_.tails
    )


def random_rotation(seed: int) -> np.ndarray:
    """A random proper 3x3 rotation."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_procrustes_recovers_a_3d_rigid_move(seed: int) -> None:
    rng = np.random.default_rng(seed)
    tmpl = rng.normal(size=(4, 30, 3))
    rots = np.stack([random_rotation(seed * 10 + i) for i in range(4)])
    trans = rng.normal(size=(4, 3))
    win = np.einsum("mij,mnj->mni", rots, tmpl) + trans[:, None]
    res, r, t = paired_procrustes(win, tmpl)
    assert np.allclose(res, 0.0, atol=1e-9)
    assert np.allclose(r, rots, atol=1e-9) and np.allclose(t, trans, atol=1e-9)
    assert np.allclose(np.linalg.det(r), 1.0)
    # a mirror image is not reachable by a proper rotation: a positive residual, never a reflection
    mirrored = win * np.array([-1.0, 1.0, 1.0])
    res_m, r_m, _ = paired_procrustes(mirrored, tmpl)
    assert (res_m > 1.0).all() and np.allclose(np.linalg.det(r_m), 1.0)


def test_rigid_interpretation_matches_tilted_input_and_bounds_the_floor_one() -> None:
    cloud = random_database(130, points=4, seed=5)
    lengths = [6, 8, 7, 5, 9, 6, 8, 7, 6, 8, 7, 6, 8, 7, 6]
    inst = instances_of(cloud, lengths)
    order = [3, 11, 0]
    x = np.concatenate([cloud[inst.start[s] : inst.start[s] + inst.length[s]] for s in order])
    tilt = random_rotation(4)
    x = x @ tilt.T + np.array([1.0, 0.3, -2.0])  # tilted off the floor: no yaw + floor move fits
    ci, cd = legal_cells(inst.length / inst.fps, RATE, 0.1, None)
    floor = interpretation(x, inst, ci, cd, RATE)
    full = interpretation(x, inst, ci, cd, RATE, rigid=True)
    finite = np.isfinite(floor.D)
    assert np.array_equal(finite, np.isfinite(full.D))
    assert (full.D[finite] <= floor.D[finite] + 1e-9).all()  # more freedom, never a worse fit
    # the cell copying the first segment, ending where it ends, fits exactly, with the tilt
    c = int(np.flatnonzero((ci == 3) & (cd == 5))[0])  # instance 3 lasts 5 frames
    assert full.D[c, 5] == pytest.approx(0.0, abs=1e-9) and floor.D[c, 5] > 1e-3
    assert np.allclose(full.rot[c, 5], tilt, atol=1e-6)  # type: ignore[index]
    # the DP with rigid alignments recovers the sequence; the floor DP cannot fit it
    res = solve(full, inst, ci, cd, k=0.0)
    assert list(ci[res.cells]) == order and res.score == pytest.approx(0.0, abs=1e-8)
    assert solve(floor, inst, ci, cd, k=0.0).score > 1e-3
    # a rigid alignment of a yaw + floor move is that move
    yawed = rigid(x @ tilt, 0.7, 0.4, -0.2)
    both = interpretation(yawed, inst, ci, cd, RATE, rigid=True)
    assert both.D[c, 5] == pytest.approx(0.0, abs=1e-9)
    src = cloud[inst.start[3] : inst.start[3] + 1]  # the segment's first frame lands on the input's
    placed = both.place(src, np.array([c]), np.array([5]))
    assert placed == pytest.approx(yawed[:1], abs=1e-6)
    # re-timing with rigid alignments keeps the recovered transform for assembly
    timed = retime(x, inst, np.array(order), np.array([0, 5, 11, 17]), 0.0, RATE, 0.1, None, 1, rigid=True)
    assert timed.rot is not None and timed.trans is not None
    assert np.allclose(timed.rot, tilt, atol=1e-6) and timed.interpretation == pytest.approx(0.0, abs=1e-8)


def tilted(motion, angle_deg: float):  # type: ignore[no-untyped-def]
    """``motion`` rotated about the +X axis through the origin (its whole body leans)."""
    from dataclasses import replace

    from motion import rotations as rot

    q = rot.from_axis_angle(np.array([1.0, 0.0, 0.0]), np.radians(angle_deg))
    root = rot.rotate(q, motion.root_positions)
    rotations = motion.rotations.copy()
    rotations[:, 0] = rot.multiply(q, rotations[:, 0])
    return replace(motion, root_positions=root, rotations=rotations)


def test_rigid_alignment_option_end_to_end() -> None:
    walks = [bvh_text(walking_biped(240, speed=1.0 + 0.2 * i, seed=i)).encode() for i in range(3)]
    # each walker controls itself: a control motion, its own target
    clips = [ClipInput(f"{role}{i}", w) for i, w in enumerate(walks) for role in ("lead", "walk")]
    spec = parse_database_spec(
        {
            "kind": "control",
            "pairs": [{"control": f"lead{i}", "target": f"walk{i}"} for i in range(3)],
            "clips": [{"bvh": f"{c.name}.bvh", "name": c.name} for c in clips],
            "segmentation": {"method": "fixed", "seconds": 0.5},
        }
    )
    library = build_library(clips, spec.fps)
    arrays = ControlEngine.build(spec, library, Collect(), lambda: False)
    arrays.update(library_to_arrays(library))
    engine = ControlEngine(library, arrays)
    lean = tilted(walking_biped(90, speed=1.2, seed=1), 25.0)
    hips_in = lean.global_positions()[:, 0]
    errors = {}
    for mode in ("floor", "rigid"):
        req = parse_job_request(
            {"engine": "control", "control": {"bvh": "c.bvh"}, "alignment": mode, "footskate": False}
        )
        req.attach_inputs({"c.bvh": bvh_text(lean).encode()})
        out = Collect()
        engine.search(req, Run(5.0, emit=out))
        sol = out.solutions[-1]
        hips = sol.motion.global_positions()[:, 0]
        errors[mode] = float(np.linalg.norm(hips - hips_in, axis=-1).mean())
        seg = sol.annotations["segments"][0]
        assert ("rotation_matrix" in seg) == (mode == "rigid")
    assert errors["rigid"] < 0.02 < errors["floor"]
    with pytest.raises(ValidationError, match="alignment"):
        parse_job_request({"engine": "control", "control": {"bvh": "c.bvh"}, "alignment": "affine"})


def test_the_database_dataclass_writes_back_the_stored_arrays() -> None:
    """:class:`engines.control.build.ControlDatabase`: ``to_arrays`` of what ``from_arrays`` read
    is the stored ``control.*`` arrays (order, dtypes, bytes; the meta JSON key for key)."""
    from engines.control.build import PREFIX, ControlDatabase
    from tests.engines.database_arrays import assert_same_arrays

    arrays = walk_engine().arrays
    assert_same_arrays(arrays, ControlDatabase.from_arrays(arrays).to_arrays(), PREFIX)
