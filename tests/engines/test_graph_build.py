"""The build half of the motion-graph engine: transition features, candidate edges (local minima
below tau), pruning to the largest strongly connected component, the edge hierarchy, root tracks."""

from __future__ import annotations

import glob
import json
import tracemalloc
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from engines.base import EngineError
from engines.graph.build import build_graph, candidate_edges, largest_component, local_minima, moving_frames
from engines.graph.features import (
    default_joint_weight,
    exact_costs,
    reduce_features,
    resolve_joint_weights,
    transition_features,
)
from engines.graph.hierarchy import LeafEdges, build_hierarchy, round_frames
from engines.graph.model import EdgeTree, RootTracks
from engines.library import ClipInput, MotionLibrary, build_library
from motion import Motion
from motion import rotations as rot
from tests.engines.emitters import Collect
from tests.motion.synthetic import walking_biped

GAIT = 30  # frames per gait cycle of walking_biped at 30 fps


def spec(**kw: Any) -> Any:
    base = {
        "tau": 1.0,
        "joint_weights": {},
        "velocity_weight": 1.0,
        "min_jump_frames": 10,
        "candidates": "auto",
    }
    base.update(kw)
    return SimpleNamespace(**base)


def library(*motions: Motion) -> MotionLibrary:
    names = tuple(f"clip{i}" for i in range(len(motions)))
    return MotionLibrary(names, motions, tuple(() for _ in motions))


def arms_up(m: Motion) -> Motion:
    """The same walk with both arms raised sideways: far from any frame of a plain walk."""
    q = m.rotations.copy()
    z = np.array([0.0, 0.0, 1.0])
    q[:, 9] = rot.multiply(q[:, 9], rot.from_axis_angle(z, np.full(m.num_frames, 1.3)))
    q[:, 11] = rot.multiply(q[:, 11], rot.from_axis_angle(z, np.full(m.num_frames, -1.3)))
    return Motion(m.skeleton, m.root_positions, q, m.fps, units="m", name="arms-up")


@pytest.fixture(scope="module")
def walks() -> MotionLibrary:
    """Two walks, different noise and heading (the torso frame makes them comparable)."""
    return library(walking_biped(150, seed=0), walking_biped(150, seed=1, heading_deg=90.0))


def dense_costs(rows: np.ndarray) -> np.ndarray:
    r = rows.astype(np.float64)
    return np.asarray(((r[:, None, :] - r[None, :, :]) ** 2).sum(-1))


# -- features -----------------------------------------------------------------------------------


def test_features_natural_continuation_is_free_and_a_frame_step_costs_one(walks: MotionLibrary) -> None:
    tf = transition_features(walks)
    assert tf.rows.dtype == np.float32 and tf.rows.shape[0] == 300
    assert tf.offsets.tolist() == [0, 150, 300]
    idx = np.arange(300)
    assert np.all(exact_costs(tf.rows, idx, idx) == 0.0)
    steps = np.sum(np.diff(tf.rows.astype(np.float64), axis=0) ** 2, axis=1)
    steps = np.delete(steps, 149)  # not a frame step: clip 0's end to clip 1's start
    assert steps.mean() == pytest.approx(1.0, rel=1e-4)
    # a walk never turns: that group is left out instead of dividing by zero
    assert tf.max_steps["turn_rate"] == 0.0 and np.all(np.isfinite(tf.rows))
    # one gait cycle later, the same pose: far cheaper than a typical frame step
    assert exact_costs(tf.rows, np.array([40]), np.array([40 + GAIT]))[0] < 0.5


def test_joint_weights_defaults_and_overrides(walks: MotionLibrary) -> None:
    assert [default_joint_weight(n) for n in ("lFoot", "Toes_L", "LowerLeg_R", "lThigh", "Hand_L")] == [
        4.0,
        4.0,
        2.0,
        2.0,
        0.5,
    ]
    assert default_joint_weight("Spine") == 1.0
    sk = walks.motions[0].skeleton
    joints = np.arange(sk.num_joints)
    w = resolve_joint_weights(sk, joints, {"head": 3.0})
    assert w[sk.names.index("head")] == 3.0 and w[sk.names.index("lFoot")] == 4.0
    with pytest.raises(EngineError, match="does not have"):
        resolve_joint_weights(sk, joints, {"nose": 1.0})
    with pytest.raises(EngineError, match=">= 0"):
        resolve_joint_weights(sk, joints, {"head": -1.0})
    # heavier feet make foot differences cost more relative to the rest
    light = transition_features(walks, {"lFoot": 0.0, "rFoot": 0.0})
    assert light.rows.shape == transition_features(walks).rows.shape


def test_pca_reduction_is_a_lower_bound(walks: MotionLibrary) -> None:
    tf = transition_features(walks)
    red, kept = reduce_features(tf.rows, 0.999)
    assert kept >= 0.999 and red.shape[1] < tf.rows.shape[1]
    rng = np.random.default_rng(0)
    a, b = rng.integers(0, 300, 500), rng.integers(0, 300, 500)
    full, low = exact_costs(tf.rows, a, b), exact_costs(red, a, b)
    assert np.all(low <= full * (1 + 1e-4) + 1e-4)
    assert np.mean(full - low) < 0.01 * np.mean(full) + 1e-3


# -- candidate edges ----------------------------------------------------------------------------


def test_gait_cycle_shift_gives_edges(walks: MotionLibrary) -> None:
    tf = transition_features(walks)
    leaves, stats = candidate_edges(tf, 1.0, 10)
    assert leaves.size > 0 and stats.minima < stats.below_tau
    assert np.all(leaves.cost < 1.0) and np.all(leaves.from_frame >= 0)
    frames = np.diff(tf.offsets)
    assert np.all(leaves.from_frame <= frames[leaves.from_clip] - 2)
    assert np.all(leaves.to_frame <= frames[leaves.to_clip] - 1)
    jump = leaves.to_frame - (leaves.from_frame + 1)
    same = leaves.from_clip == leaves.to_clip
    assert np.all(np.abs(jump[same]) >= 10)
    # within a clip: a cut one gait cycle forward (and back), cheap
    near = same & (np.abs(np.abs(jump) - GAIT) <= 1)
    assert np.any(near & (jump > 0)) and np.any(near & (jump < 0))
    assert np.median(leaves.cost[near]) < 0.5
    # between the two walks (different heading): cuts to the same gait phase
    cross = ~same
    assert np.any(cross & (leaves.from_clip == 0)) and np.any(cross & (leaves.from_clip == 1))
    phase = np.abs((jump[cross] + GAIT // 2) % GAIT - GAIT // 2)
    assert np.median(phase) <= 1
    # costs are exact: C(from + 1, to) on the full features
    rows_from = tf.offsets[leaves.from_clip] + leaves.from_frame + 1
    rows_to = tf.offsets[leaves.to_clip] + leaves.to_frame
    np.testing.assert_allclose(leaves.cost, exact_costs(tf.rows, rows_from, rows_to), rtol=1e-5, atol=1e-6)


def brute_force_minima(
    rows: np.ndarray, offsets: np.ndarray, tau: float, min_jump: int
) -> set[tuple[int, int]]:
    m = dense_costs(rows)
    clip = np.repeat(np.arange(offsets.size - 1), np.diff(offsets))
    n = rows.shape[0]
    out = set()
    for x in range(n):
        for y in range(x + 1, n):
            v = m[x, y]
            if v >= tau or (clip[x] == clip[y] and y - x < min_jump):
                continue
            ok = True
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    a, b = x + dx, y + dy
                    if (dx, dy) == (0, 0) or not (0 <= a < n and 0 <= b < n):
                        continue
                    if clip[a] != clip[x] or clip[b] != clip[y]:
                        continue
                    earlier = (dx, dy) < (0, 0)
                    if (v >= m[a, b]) if earlier else (v > m[a, b]):
                        ok = False
            if ok:
                out.add((x, y))
    return out


@pytest.mark.parametrize("tile", [7, 16, 64])
def test_tiled_scan_matches_brute_force(tile: int) -> None:
    rng = np.random.default_rng(3)
    # smooth random trajectories (so minima are structured), three clips of uneven length
    lengths = [23, 40, 17]
    parts = [np.cumsum(rng.normal(size=(k, 5)), axis=0) * 0.3 for k in lengths]
    rows = np.concatenate(parts).astype(np.float32)
    offsets = np.concatenate(([0], np.cumsum(lengths))).astype(np.int64)
    tau = float(np.quantile(dense_costs(rows), 0.3))
    x, y, v, stats = local_minima(rows, offsets, tau, 4, tile=tile, workers=2)
    got = set(zip(x.tolist(), y.tolist(), strict=True))
    assert got == brute_force_minima(rows, offsets, tau, 4)
    assert len(got) == x.size and stats.minima == x.size
    np.testing.assert_allclose(v, dense_costs(rows)[x, y], rtol=1e-4, atol=1e-4)


def test_local_minima_keep_a_few_edges_per_group(walks: MotionLibrary) -> None:
    tf = transition_features(walks)
    tau = 1.0
    x, y, _, stats = local_minima(tf.rows, tf.offsets, tau, 10)
    m = dense_costs(tf.rows)
    kept = np.zeros(m.shape, dtype=bool)
    kept[x, y] = True
    kept |= kept.T
    assert stats.minima <= 0.2 * stats.below_tau
    for s in (slice(0, 150), slice(150, 300)):
        for t in (slice(0, 150), slice(150, 300)):
            mask = m[s, t] < tau
            if s == t:
                i, j = np.indices(mask.shape)
                mask &= np.abs(j - i) >= 10
            labels, n = ndimage.label(mask, structure=np.ones((3, 3)))
            assert n >= 4  # the gait-cycle valleys
            per_group = ndimage.sum(kept[s, t], labels, index=np.arange(1, n + 1))
            sizes = ndimage.sum(mask, labels, index=np.arange(1, n + 1))
            big = sizes >= 10
            assert np.all(per_group[big] >= 1)  # every group keeps its best cut...
            assert np.all(per_group[big] <= 0.35 * sizes[big])  # ...and few of its others


# -- pruning ------------------------------------------------------------------------------------


def test_scc_drops_an_isolated_clip_and_says_why() -> None:
    lib = library(walking_biped(150, seed=0), walking_biped(150, seed=1), arms_up(walking_biped(150, seed=2)))
    emit = Collect()
    arrays = build_graph(spec(), lib, emit, lambda: False)
    report = json.loads(str(arrays["graph.report"]))
    assert [d["clip"] for d in report["dropped_clips"]] == ["clip2"]
    assert "tau" in report["dropped_clips"][0]["reason"]
    tree = EdgeTree.from_arrays(arrays)
    assert not np.any(tree.from_clip == 2) and not np.any(tree.to_clip == 2)
    assert report["leaf_edges"] == int(tree.is_leaf.sum()) > 0


def test_largest_component_reasons() -> None:
    # 0 <-> 1 is the main cycle; 0 -> 2 (a dead end); 3 -> 0 (unreachable); 4 <-> 5 apart; 6 alone
    pairs = [(0, 1), (1, 0), (0, 2), (3, 0), (4, 5), (5, 4), (6, 6)]
    f, t = np.array(pairs).T
    z = np.zeros(len(pairs), dtype=np.int64)
    leaves = LeafEdges(f, z + 5, t, z + 20, np.full(len(pairs), 0.5))
    frames = np.array([100, 100, 50, 50, 60, 60, 10], dtype=np.int64)
    keep, dropped = largest_component(leaves, frames, tuple("abcdefg"))
    assert keep.tolist() == [True, True, False, False, False, False, False]
    reasons = {d["clip"]: d["reason"] for d in dropped}
    assert reasons["c"].startswith("dead end") and reasons["d"].startswith("unreachable")
    assert reasons["e"].startswith("no transition to or from the main component")
    assert "1 other clip(s) of its strongly connected group" in reasons["f"]
    assert reasons["g"].startswith("no transition below tau")
    # the largest by frames, not by clips: a lone long clip wins over a short cycle
    frames[6] = 500
    keep, dropped = largest_component(leaves, frames, tuple("abcdefg"))
    assert keep.tolist() == [False] * 6 + [True]
    assert {d["clip"] for d in dropped} == set("abcdef")
    # ... but a long clip without any transition is no component to keep
    frames = np.append(frames, 10_000)
    keep, dropped = largest_component(leaves, frames, tuple("abcdefgh"))
    assert keep.tolist() == [False] * 6 + [True]
    assert {d["clip"]: d["reason"] for d in dropped}["h"].startswith("no transition below tau")


# -- hierarchy ----------------------------------------------------------------------------------


def check_tree(tree: EdgeTree, leaves: LeafEdges) -> np.ndarray:
    """Assert the contract of :mod:`engines.graph.model` and return each leaf's root."""
    e, n = leaves.size, tree.size
    assert np.all(tree.is_leaf[:e]) and not np.any(tree.is_leaf[e:])
    for name in ("from_clip", "from_frame", "to_clip", "to_frame", "cost"):
        np.testing.assert_array_equal(getattr(tree, name)[:e], getattr(leaves, name))
    inner = np.arange(e, n)
    assert np.all(tree.left[inner] >= 0) and np.all(tree.right[inner] >= 0)
    assert np.all(tree.parent[tree.left[inner]] == inner) and np.all(tree.parent[tree.right[inner]] == inner)
    child = np.flatnonzero(tree.parent >= 0)
    p = tree.parent[child]
    assert np.all((tree.left[p] == child) | (tree.right[p] == child))
    assert child.size == 2 * inner.size  # binary: every non-root is one child of one parent
    # every leaf reaches exactly one root; the sums of the leaves below every node
    sums = np.zeros((n, 4))
    cur = np.arange(e)
    vals = np.stack((np.ones(e), leaves.from_frame, leaves.to_frame, leaves.cost), axis=1)
    np.add.at(sums, cur, vals)
    for _ in range(n):
        up = tree.parent[cur] >= 0
        if not up.any():
            break
        cur, vals = tree.parent[cur[up]], vals[up]
        np.add.at(sums, cur, vals)
    root = np.arange(e)
    for _ in range(n):
        up = tree.parent[root] >= 0
        if not up.any():
            break
        root[up] = tree.parent[root[up]]
    assert np.all(tree.parent[root] == -1)
    assert set(np.unique(root).tolist()) == set(tree.roots.tolist())
    assert tree.roots.size <= e
    np.testing.assert_array_equal(tree.from_frame[inner], round_frames(sums[inner, 1] / sums[inner, 0]))
    np.testing.assert_array_equal(tree.to_frame[inner], round_frames(sums[inner, 2] / sums[inner, 0]))
    # stored costs are float32 (EdgeTree.to_arrays)
    np.testing.assert_allclose(tree.cost[inner], sums[inner, 3] / sums[inner, 0], rtol=1e-6)
    # a node's clips are its leaves' clips
    np.testing.assert_array_equal(tree.from_clip[root], leaves.from_clip)
    np.testing.assert_array_equal(tree.to_clip[root], leaves.to_clip)
    return root


def test_hierarchy_invariants_on_built_edges(walks: MotionLibrary) -> None:
    leaves, _ = candidate_edges(transition_features(walks), 1.0, 10)
    tree = build_hierarchy(leaves)
    root = check_tree(tree, leaves)
    assert 0 < tree.roots.size < leaves.size
    # forward and backward jumps within a clip are never averaged together
    same = leaves.from_clip == leaves.to_clip
    fwd = leaves.to_frame > leaves.from_frame
    for r in np.unique(root[same]):
        assert np.unique(fwd[same & (root == r)]).size == 1
    # clusters are compact along the gait-phase structure: a root's leaves share a clip pair
    for r in np.unique(root):
        members = root == r
        assert np.unique(leaves.from_clip[members]).size == 1 and np.unique(leaves.to_clip[members]).size == 1


def test_hierarchy_invariants_on_random_edges_and_elongated_groups() -> None:
    rng = np.random.default_rng(1)
    k = 30000
    raw = np.stack(
        (rng.integers(0, 40, k), rng.integers(0, 400, k), rng.integers(0, 40, k), rng.integers(0, 400, k))
    )
    key = np.unique(raw.T, axis=0)
    leaves = LeafEdges(key[:, 0], key[:, 1], key[:, 2], key[:, 3], rng.random(len(key)))
    check_tree(build_hierarchy(leaves), leaves)
    # one long thin group (a diagonal valley): several roots, each a contiguous stretch of it
    f = np.arange(0, 3000, 3)
    thin = LeafEdges(np.zeros(f.size, np.int64), f, np.ones(f.size, np.int64), f + 7, np.full(f.size, 0.2))
    tree = build_hierarchy(thin)
    root = check_tree(tree, thin)
    assert 2 <= tree.roots.size <= int(np.ceil(np.sqrt(f.size)))
    spans = [np.ptp(f[root == r]) for r in np.unique(root)]
    assert max(spans) < 3000 / tree.roots.size * 3
    # trivial inputs
    assert build_hierarchy(LeafEdges.empty()).size == 0
    one = build_hierarchy(thin.take(np.array([5])))
    assert one.size == 1 and one.roots.tolist() == [0]


def test_hierarchy_scales_to_many_edges() -> None:
    """200,000 leaf edges make a tree of fewer than twice as many nodes (how long it takes is
    ``python bench/graph_build.py --sets hierarchy``, not a test)."""
    rng = np.random.default_rng(2)
    k = 200_000
    raw = np.stack(
        (rng.integers(0, 60, k), rng.integers(0, 2000, k), rng.integers(0, 60, k), rng.integers(0, 2000, k))
    )
    key = np.unique(raw.T, axis=0)
    leaves = LeafEdges(key[:, 0], key[:, 1], key[:, 2], key[:, 3], rng.random(len(key)))
    tree = build_hierarchy(leaves)
    assert tree.size < 2 * leaves.size


# -- build_graph --------------------------------------------------------------------------------


def turning_walk(frames: int = 150) -> Motion:
    """A walk whose heading turns by 270 degrees over the clip (the heading must unwrap)."""
    m = walking_biped(frames, seed=4)
    yaw = np.linspace(0.0, np.radians(270.0), frames)
    q = m.rotations.copy()
    q[:, 0] = rot.from_yaw(yaw)
    return Motion(m.skeleton, m.root_positions, q, m.fps, units="m", name="turn")


def test_build_graph_arrays_report_tracks_and_progress(walks: MotionLibrary) -> None:
    lib = library(*walks.motions, turning_walk())
    emit = Collect()
    arrays = build_graph(spec(), lib, emit, lambda: False)
    tree = EdgeTree.from_arrays(arrays)
    tracks = RootTracks.from_arrays(arrays)
    report = json.loads(str(arrays["graph.report"]))
    assert arrays["graph.report"].shape == () and arrays["graph.report"].dtype.kind == "U"
    for key in ("frames", "clips", "leaf_edges", "root_edges", "tree_nodes", "dropped_clips", "build_s"):
        assert key in report
    assert report["frames"] == 450 and report["clips"] == 3
    assert report["leaf_edges"] == int(tree.is_leaf.sum()) and report["root_edges"] == tree.roots.size
    assert report["tree_nodes"] == tree.size
    check_tree(
        tree,
        LeafEdges(
            *(
                getattr(tree, k)[tree.is_leaf]
                for k in ("from_clip", "from_frame", "to_clip", "to_frame", "cost")
            )
        ),
    )
    assert tracks.offsets.tolist() == [0, 150, 300, 450]
    assert tracks.root_xz.shape == (450, 2) and tracks.root_yaw.shape == (450,)
    np.testing.assert_allclose(tracks.root_xz[:150], walks.motions[0].root_positions[:, [0, 2]])
    turn = tracks.root_yaw[300:]
    assert turn[-1] - turn[0] == pytest.approx(np.radians(270.0), abs=0.05)  # unwrapped
    assert np.all(np.abs(np.diff(turn)) < 0.2)
    fractions = [f for f, _ in emit.progress_events]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0 and len(fractions) >= 3
    assert all(0.0 <= f <= 1.0 for f in fractions)


def test_build_graph_cancel_and_errors(walks: MotionLibrary) -> None:
    calls = {"n": 0}

    def stop_soon() -> bool:
        calls["n"] += 1
        return calls["n"] > 1

    with pytest.raises(InterruptedError, match="build cancelled"):
        build_graph(spec(), walks, Collect(), stop_soon, tile=32)
    with pytest.raises(EngineError, match="raise tau"):
        build_graph(spec(tau=1e-9), walks, Collect(), lambda: False)
    with pytest.raises(EngineError, match="joint_weights"):
        build_graph(spec(joint_weights={"nose": 2.0}), walks, Collect(), lambda: False)


def test_build_graph_is_deterministic_and_worker_independent(walks: MotionLibrary) -> None:
    a = build_graph(spec(), walks, Collect(), lambda: False, tile=40, workers=1)
    b = build_graph(spec(), walks, Collect(), lambda: False, tile=40, workers=3)
    c = build_graph(spec(), walks, Collect(), lambda: False)
    for key in EdgeTree.from_arrays(a).to_arrays():
        np.testing.assert_array_equal(a[key], b[key])
        np.testing.assert_array_equal(a[key], c[key])


# -- real data ----------------------------------------------------------------------------------

BANDAI = Path(__file__).resolve().parents[3] / "shared" / "data" / "bandai-namco" / "dataset-2"


@pytest.mark.skipif(not BANDAI.exists(), reason="needs ../shared/data/bandai-namco")
def test_bandai_locomotion_build() -> None:
    files: list[str] = []
    for kind in ("walk", "walk-turn-left", "walk-turn-right", "run"):
        files += sorted(glob.glob(str(BANDAI / f"dataset-2_{kind}_normal_*.bvh")))[:5]
    assert len(files) == 20
    lib = build_library([ClipInput(Path(f).stem, Path(f).read_bytes()) for f in files], fps=30.0)
    tracemalloc.start()
    arrays = build_graph(spec(), lib, Collect(), lambda: False)  # its time: bench/graph_build.py
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    report = json.loads(str(arrays["graph.report"]))
    assert "joint_Root" not in report["joint_weights"] and report["joint_weights"]["Foot_L"] == 4.0
    assert peak < 600e6, f"peak {peak / 1e6:.0f} MB for {lib.total_frames} frames"
    tree = EdgeTree.from_arrays(arrays)
    kind = np.array([n.split("_")[1] for n in lib.names])
    leaf = tree.is_leaf
    fk, tk = kind[tree.from_clip[leaf]], kind[tree.to_clip[leaf]]
    for a, b in (("walk", "walk-turn-left"), ("walk-turn-left", "walk"), ("walk", "walk-turn-right")):
        assert np.any((fk == a) & (tk == b)), f"no edge from {a} to {b}"
    # the torso frame: the body root is the hips, not Bandai's static joint_Root at the origin
    tracks = RootTracks.from_arrays(arrays)
    assert np.ptp(tracks.root_xz[: tracks.offsets[1]], axis=0).max() > 1.0
    assert report["frames"] == lib.total_frames and report["leaf_edges"] > 0


def test_largest_component_prefers_locomotion() -> None:
    # 0 <-> 1 (gestures, 300 frames) and 2 <-> 3 (walks, 200 frames, 150 of them moving)
    pairs = [(0, 1), (1, 0), (2, 3), (3, 2)]
    f, t = np.array(pairs).T
    z = np.zeros(len(pairs), dtype=np.int64)
    leaves = LeafEdges(f, z + 5, t, z + 20, np.full(len(pairs), 0.5))
    frames = np.array([150, 150, 100, 100], dtype=np.int64)
    keep, dropped = largest_component(leaves, frames, tuple("abcd"))
    assert keep.tolist() == [True, True, False, False]  # by frames
    keep, dropped = largest_component(leaves, frames, tuple("abcd"), np.array([0, 0, 80, 70]))
    assert keep.tolist() == [False, False, True, True]
    assert [(d["clip"], d["frames"]) for d in dropped] == [("a", 150), ("b", 150)]


def test_moving_frames_counts_frames_faster_than_the_locomotion_speed() -> None:
    x = np.concatenate((np.arange(10) * 0.05, np.arange(5) * 0.01))  # 1.5 m/s, then 0.3 m/s at 30 fps
    tracks = RootTracks(np.array([0, 10, 15]), np.stack((x, np.zeros(15)), axis=1), np.zeros(15))
    assert moving_frames(tracks, 30.0).tolist() == [9, 0]


def test_a_graph_database_stores_its_motion_as_float32(walks: MotionLibrary) -> None:
    """The engine's build replaces the library's float64 rotations and translations with float32
    ones (what the store writes: the engine's arrays after the library's); the loaded engine reads
    the same motion back to float32 rounding."""
    from engines.graph.engine import GraphEngine
    from engines.library import library_from_arrays, library_to_arrays
    from engines.registry import parse_database_spec

    lib = library(walking_biped(150, seed=0), arms_up(walking_biped(150, seed=1)))
    db = parse_database_spec({"kind": "graph", "clips": [{"bvh": "x.bvh"}]})
    arrays = library_to_arrays(lib)
    arrays.update(GraphEngine.build(db, lib, Collect(), lambda: False))
    assert arrays["library.rotations"].dtype == np.float32
    assert arrays["library.joint_translations"].dtype == np.float32
    assert arrays["library.root_positions"].dtype == np.float64
    back = GraphEngine(library_from_arrays(arrays), arrays).library
    for m, b in zip(lib.motions, back.motions, strict=True):
        assert b.rotations.dtype == np.float64
        np.testing.assert_allclose(b.rotations, m.rotations, atol=1e-7)
        np.testing.assert_array_equal(b.root_positions, m.root_positions)
        pos = m.global_positions()
        np.testing.assert_allclose(b.global_positions(), pos, atol=1e-6 * max(1.0, np.abs(pos).max()))
