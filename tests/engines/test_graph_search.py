"""The search half of the motion-graph engine: paths, placement, scores, mutations, assembly, the
anytime loop. The graph is built by hand (``graph_synthetic``), independent of the build half."""

from __future__ import annotations

import glob
import itertools
from dataclasses import replace
from pathlib import Path as FsPath
from typing import Any

import numpy as np
import pytest

from engines import base as engines_base
from engines.base import EngineError, Run, Solution, Stopped
from engines.graph.assemble import assemble, body_frames, quality_inputs
from engines.graph.model import EdgeTree, RootTracks
from engines.graph.paths import (
    GraphIndex,
    Path,
    PathBatch,
    batch_pieces,
    batch_valid,
    compose2,
    invert2,
    path_pieces,
    trim,
)
from engines.graph.score import Problem, compile_problem, evaluate, score_batch
from engines.graph.search import GraphSearch
from engines.library import MotionLibrary
from motion import Motion, Skeleton
from motion import rotations as rot
from motion.quality import assess
from schemas.graph import GraphRequest
from tests.engines.emitters import Collect

from .graph_synthetic import synthetic_graph

Graph = tuple[MotionLibrary, EdgeTree, RootTracks]


@pytest.fixture(scope="module")
def graph() -> Graph:
    return synthetic_graph()


def request(**kw: Any) -> GraphRequest:
    body: dict[str, Any] = {
        "engine": "graph",
        "frames": 240,
        "seed": 3,
        "alternatives": 3,
        "constraints": [
            {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
            {"type": "body", "frame": 239, "position": [2.0, 4.0], "heading_deg": 60.0},
        ],
    }
    body.update(kw)
    return GraphRequest.model_validate(body)


def python_valid(tree: EdgeTree, frames: np.ndarray, p: Path) -> bool:
    """The contract's validity rule, one edge at a time."""
    if not 0 <= p.start_frame < frames[p.start_clip]:
        return False
    clip, frame = p.start_clip, p.start_frame
    for e in p.edges:
        if tree.from_clip[e] != clip or tree.from_frame[e] < frame:
            return False
        clip, frame = int(tree.to_clip[e]), int(tree.to_frame[e])
    return True


def searcher(graph: Graph, seed: int = 0, **kw: Any) -> GraphSearch:
    library, tree, tracks = graph
    return GraphSearch(library, tree, tracks, seed, **kw)


def prime(gs: GraphSearch, req: GraphRequest) -> None:
    """Set up a searcher's problem as ``run`` does (to call its parts directly)."""
    gs._problem = compile_problem(req, gs.library, gs.tracks)
    gs._useful = None
    gs._seen = set()


# -- paths and placement -----------------------------------------------------------------------


def test_every_mutation_is_a_valid_path(graph: Graph) -> None:
    library, tree, tracks = graph
    gs = searcher(graph)
    req = request()
    prime(gs, req)
    rng = np.random.default_rng(0)
    seeds = gs._random_seeds(rng, 12)
    frames = np.diff(tracks.offsets)
    checked = 0
    for i in range(seeds.size):
        path = trim(gs.index_, seeds.path(i), req.frames or 0)
        assert python_valid(tree, frames, path)
        cands = gs.mutations(path, rng)
        assert cands.size > 0
        assert batch_valid(gs.index_, cands).all()
        for k in rng.choice(cands.size, size=min(cands.size, 40), replace=False):
            assert python_valid(tree, frames, cands.path(int(k)))
        checked += cands.size
    assert checked > 1000
    # and the validity check itself rejects broken chains
    bad = Path(0, 10, (int(tree.roots[0]), int(tree.roots[0])))
    assert not batch_valid(gs.index_, PathBatch.from_paths([bad]))[0] or python_valid(tree, frames, bad)


def test_one_edge_replacements_are_capped_and_only_above_the_cap(graph: Graph) -> None:
    """``max_one`` bounds the 1-edge replacements per step (0-edge ones kept); below it the batch
    is the same and no random number is drawn (smaller databases' searches do not change)."""
    req = request()
    free, capped = searcher(graph, max_one=10**9), searcher(graph, max_one=5)
    prime(free, req)
    prime(capped, req)
    path = trim(free.index_, free._random_seeds(np.random.default_rng(0), 1).path(0), req.frames or 0)

    def one_edge(batch: PathBatch) -> set[tuple[int, ...]]:
        """Rows that differ from the path by a splice with one new edge (keyed by their edges)."""
        rows = {tuple(int(e) for e in r if e >= 0) for r in batch.edges}
        return {r for r in rows if len(set(r) - set(path.edges)) == 1}

    r1, r2 = np.random.default_rng(7), np.random.default_rng(7)
    full = free.mutations(path, r1, 1)
    cut = capped.mutations(path, r2, 1)
    assert cut.size < full.size
    assert batch_valid(capped.index_, cut).all()
    assert one_edge(cut) <= one_edge(full)
    assert r1.random() != r2.random()  # the cap drew its subset from the search's generator
    same = searcher(graph, max_one=10**9)
    prime(same, req)
    r3, r4 = np.random.default_rng(7), np.random.default_rng(7)
    again = same.mutations(path, r3, 1)
    assert np.array_equal(again.edges, free.mutations(path, r4, 1).edges)
    assert r3.random() == r4.random() == np.random.default_rng(7).random()


def test_two_hops_are_every_valid_root_pair_in_table_order(graph: Graph) -> None:
    """``two_hops(a, -1)``: every ``(h1, h2)`` with ``h1`` leaving ``a``, ``h2`` leaving where it
    lands at or after its landing frame, ordered by middle clip, then ``h1`` (from frame), then
    ``h2`` (from frame), as the per-clip tables gave them (the 2-edge mutations' random subset
    depends on this order)."""
    _, tree, _ = graph
    idx = searcher(graph).index_
    roots = idx.roots
    seen = 0
    for a in range(idx.n_clips):
        out_a = roots[tree.from_clip[roots] == a]
        want: list[tuple[int, int]] = []
        for mid in sorted({int(c) for c in tree.to_clip[out_a]}):
            for h1 in out_a[tree.to_clip[out_a] == mid]:
                for h2 in roots[tree.from_clip[roots] == mid]:
                    if tree.to_frame[h1] <= tree.from_frame[h2]:
                        want.append((int(h1), int(h2)))
        h1s, h2s = idx.two_hops(a, -1)
        assert list(zip(h1s.tolist(), h2s.tolist(), strict=True)) == want
        seen += len(want)
    assert seen > 100


def test_pieces_truncate_to_the_length_and_flag_short_paths(graph: Graph) -> None:
    _, tree, tracks = graph
    index = GraphIndex(tree, tracks)
    e = int(np.flatnonzero((tree.from_clip == 0) & (tree.to_clip == 2) & (tree.parent < 0))[0])
    p = Path(0, 0, (e,))
    pieces = path_pieces(index, p, 100)
    assert pieces.frames == 100 and pieces.start[0] == 0
    assert pieces.last[0] == tree.from_frame[e] and pieces.clip.tolist() == [0, 2]
    assert pieces.total == tree.from_frame[e] + 1 + tracks.frames(2) - tree.to_frame[e]
    short = path_pieces(index, Path(0, 140), 100)
    assert short.frames == 10 and short.total == 10
    bp = batch_pieces(index, PathBatch.from_paths([p, Path(0, 140)]), 100)
    assert bp.count.sum(axis=1).tolist() == [100, 10]


def test_placement_continues_where_the_previous_piece_ended(graph: Graph) -> None:
    library, tree, tracks = graph
    gs = searcher(graph)
    req = request()
    prime(gs, req)
    seeds = gs._random_seeds(np.random.default_rng(5), 8)
    index = gs.index_
    for i in range(seeds.size):
        ev = evaluate(index, gs._problem, seeds.path(i))
        pl, pc = ev.placement, ev.pieces
        for j in range(1, pc.clip.size):
            # the previous piece's next frame (inside its clip here, or extrapolated)
            c, f = int(pc.clip[j - 1]), int(pc.last[j - 1])
            if f + 1 >= tracks.frames(c):
                continue
            y, xz = index.ground(np.array([c]), np.array([f + 1]))
            th, sh = compose2(pl.theta[j - 1], pl.shift[j - 1], y[0], xz[0])
            got_xz, got_yaw = pl.root(np.array([pc.start[j]]))
            np.testing.assert_allclose(got_xz[0], sh, atol=1e-9)
            assert abs(got_yaw[0] - th) < 1e-9
        # the first body constraint places the motion
        xz0, yaw0 = pl.root(np.array([0]))
        np.testing.assert_allclose(xz0[0], [0.0, 0.0], atol=1e-9)
        assert abs(yaw0[0]) < 1e-9


def test_edge_transforms_match_the_tracks(graph: Graph) -> None:
    _, tree, tracks = graph
    index = GraphIndex(tree, tracks)
    inside = tree.from_frame + 1 < index.frames[tree.from_clip]
    a = index.ground(tree.from_clip[inside], tree.from_frame[inside] + 1)
    b = invert2(*index.ground(tree.to_clip[inside], tree.to_frame[inside]))
    th, sh = compose2(a[0], a[1], b[0], b[1])
    np.testing.assert_allclose(index.edge_theta[inside], th, atol=1e-12)
    np.testing.assert_allclose(index.edge_shift[inside], sh, atol=1e-12)


# -- scores ------------------------------------------------------------------------------------


def test_score_terms_use_the_papers_units(graph: Graph) -> None:
    library, tree, tracks = graph
    index = GraphIndex(tree, tracks)
    # clip "straight" walks 1.2 m/s along +Z: 60 frames later it is 2.36 m further
    p = Path(0, 0)
    base = request(
        frames=120,
        constraints=[
            {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
            {"type": "body", "frame": 60, "position": [0.3, 2.36], "heading_deg": 10.0},
        ],
    )
    ev = evaluate(index, compile_problem(base, library, tracks), p)
    # the score charges the correction assembly will make: the heading error, spread as a turn
    # of every step since frame 0, and the position error left after that turn
    xz, yaw = ev.placement.root(np.arange(61))
    turn = np.radians(10.0) - yaw[60]
    alpha = turn * np.arange(61) / 60
    c, s = np.cos(alpha[1:]), np.sin(alpha[1:])
    step = np.diff(xz, axis=0)
    turned = xz[0] + np.sum(
        np.stack((c * step[:, 0] + s * step[:, 1], -s * step[:, 0] + c * step[:, 1]), 1), 0
    )
    d = np.linalg.norm(turned - [0.3, 2.36])
    expected = (d / 0.3) ** 2 + (turn / np.radians(10.0)) ** 2
    # (the search estimates the turn on a grid of frames: a few millimetres of difference)
    assert ev.terms["body"] == pytest.approx(expected, rel=2e-2)
    assert ev.terms["continuity"] == 0.0 and ev.terms["length"] == 0.0
    short = evaluate(index, compile_problem(request(frames=170, constraints=[]), library, tracks), p)
    assert short.terms["length"] == pytest.approx((20 / 10) ** 2)


def test_label_and_obstacle_terms(graph: Graph) -> None:
    library, tree, tracks = graph
    index = GraphIndex(tree, tracks)
    want_slow = request(frames=100, constraints=[{"type": "label", "label": "slow", "start": 0, "end": 50}])
    prob = compile_problem(want_slow, library, tracks)
    assert evaluate(index, prob, Path(1, 0)).terms["label"] == 0.0
    assert evaluate(index, prob, Path(0, 0)).terms["label"] == pytest.approx(50 / 10)
    disc = request(
        frames=100,
        constraints=[
            {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
            {"type": "obstacle", "disc": {"center": [0.0, 2.0], "radius": 0.5}},
        ],
    )
    prob = compile_problem(disc, library, tracks)
    assert evaluate(index, prob, Path(0, 0)).terms["obstacle"] > 1.0  # walks straight through it
    square = request(
        frames=100,
        constraints=[
            {"type": "body", "frame": 0, "position": [5.0, 0.0], "heading_deg": 0.0},
            {"type": "obstacle", "polygon": [[-1, 1], [1, 1], [1, 3], [-1, 3]]},
        ],
    )
    assert evaluate(index, compile_problem(square, library, tracks), Path(0, 0)).terms["obstacle"] == 0.0


def test_bad_requests_are_engine_errors(graph: Graph) -> None:
    library, _, tracks = graph
    for constraints, match in (
        ([{"type": "joint", "frame": 3, "joint": "nose", "position": [0, 1, 0]}], "no joint named 'nose'"),
        ([{"type": "pose", "frame": 3, "clip": "nope", "clip_frame": 0}], "no clip named 'nope'"),
        ([{"type": "pose", "frame": 3, "clip": "slow", "clip_frame": 999}], "has 150 frames"),
        ([{"type": "body", "frame": 500, "position": [0, 0]}], "outside the motion"),
        ([{"type": "label", "label": "dance", "start": 0, "end": 9}], "carries the label 'dance'"),
    ):
        with pytest.raises(EngineError, match=match):
            compile_problem(request(constraints=constraints), library, tracks)


# -- assembly ----------------------------------------------------------------------------------


def test_assembly_meets_body_constraints_exactly(graph: Graph) -> None:
    library, tree, tracks = graph
    gs = searcher(graph)
    req = request(
        constraints=[
            {"type": "body", "frame": 10, "position": [1.0, -1.0], "heading_deg": 30.0},
            {"type": "body", "frame": 120, "position": [1.5, 3.0]},
            {"type": "body", "frame": 239, "position": [4.0, 4.0], "heading_deg": 100.0},
        ]
    )
    prime(gs, req)
    seeds = gs._random_seeds(np.random.default_rng(2), 6)
    for i in range(seeds.size):
        ev = evaluate(gs.index_, gs._problem, seeds.path(i))
        if ev.pieces.frames < 240:
            continue
        motion, prov = assemble(library, tracks, ev.pieces, ev.placement, req)
        assert motion.num_frames == 240 and len(prov) == 240
        xz, yaw = body_frames(motion)
        for c in req.constraints:
            assert c.frame is not None
            assert np.linalg.norm(xz[c.frame] - c.position) < 1e-3
            if c.heading_deg is not None:
                err = (np.degrees(yaw[c.frame]) - c.heading_deg + 180) % 360 - 180
                assert abs(err) < 0.1
        errors = measured(motion, prov, gs._problem, library)
        assert errors["length"]["frames"] == 0 and errors["length"]["satisfied"]
        assert errors["body[2]"]["position_cm"] < 0.1 and errors["body[2]"]["heading_deg"] < 0.1
        # provenance: the source frames of the pieces, in order
        assert prov[0] == (library.names[int(ev.pieces.clip[0])], int(ev.pieces.first[0]))


def measured(motion: Motion, prov: list[tuple[str, int]], problem: Problem, library: MotionLibrary) -> dict:
    """The quality report's constraint errors of an assembled motion."""
    return assess(
        motion, quality_inputs(motion, prov, np.zeros(0, np.intp), problem, library)
    ).constraint_errors


def _with_reference_root(library: MotionLibrary, moving: int = -1) -> MotionLibrary:
    """The library with a Bandai-style ``joint_Root`` above each clip's root (at the origin, the
    old root's motion as its translated child); in clip ``moving`` joint 0 drifts and turns
    instead and the child makes up for it (the same global poses), as in four Bandai clips."""
    wrapped = []
    for i, m in enumerate(library.motions):
        sk = m.skeleton
        new = Skeleton(
            ("joint_Root", *sk.names),
            np.concatenate(([-1], sk.parents + 1)),
            np.concatenate((np.zeros((1, 3)), sk.offsets)),
            (("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"), *sk.channels),
            sk.end_site_parents + 1,
            sk.end_site_offsets,
        )
        q = np.concatenate((np.tile([0.0, 0.0, 0.0, 1.0], (m.num_frames, 1, 1)), m.rotations), axis=1)
        root = np.zeros((m.num_frames, 3))
        child = m.root_positions[:, None].copy()
        if i == moving:
            f = np.arange(m.num_frames, dtype=np.float64)
            root = np.stack((0.03 * f, 0.0 * f, -0.04 * f), axis=1)
            q[:, 0] = rot.from_yaw(0.01 * f)
            inv = rot.conjugate(q[:, 0])
            child[:, 0] = rot.rotate(inv, m.root_positions - root)
            q[:, 1] = rot.multiply(inv, m.rotations[:, 0])
        wrapped.append(Motion(new, root, q, m.fps, child, "m", m.name))
    return replace(library, motions=tuple(wrapped))


def test_assembly_with_a_static_reference_root(graph: Graph) -> None:
    """Bandai-style skeletons: joint 0 never moves, the hips carry the motion as a translated
    child. The placement and corrections go to the hips; joint 0 stays put."""
    library, tree, tracks = graph
    lib2 = _with_reference_root(library)
    req = request()
    gs = GraphSearch(lib2, tree, tracks, 1)
    prime(gs, req)
    seeds = gs._random_seeds(np.random.default_rng(4), 4)
    ev = evaluate(
        gs.index_, gs._problem, seeds.path(int(np.argmax([len(seeds.path(i).edges) for i in range(4)])))
    )
    motion, _ = assemble(lib2, tracks, ev.pieces, ev.placement, req)
    assert np.abs(motion.root_positions).max() == 0.0  # joint 0 untouched
    xz, yaw = body_frames(motion)
    np.testing.assert_allclose(xz[239], [2.0, 4.0], atol=1e-6)
    assert abs((np.degrees(yaw[239]) - 60 + 180) % 360 - 180) < 1e-4
    # same output as the plain skeleton, joint for joint
    plain, _ = assemble(library, tracks, ev.pieces, ev.placement, req)
    np.testing.assert_allclose(motion.global_positions()[:, 1:], plain.global_positions(), atol=1e-9)


@pytest.mark.parametrize("moving", [0, 1, 2])
def test_assembly_pins_a_reference_root_that_moves_in_a_few_clips(graph: Graph, moving: int) -> None:
    """A clip whose joint 0 moves (its child making up for it) among clips where it stays put:
    assembly pins it to the usual pose, so smoothing never swings a body about the origin and the
    output is the plain skeleton's, joint for joint (joint 0 never moves)."""
    library, tree, tracks = graph
    lib2 = _with_reference_root(library, moving)
    req = request()
    gs = GraphSearch(lib2, tree, tracks, 1)
    prime(gs, req)
    seeds = gs._random_seeds(np.random.default_rng(4), 64)
    used = [i for i in range(64) if moving in path_pieces(gs.index_, seeds.path(i), 240).clip[1:]]
    assert used, "no seed plays the moving clip after a cut"
    ev = evaluate(gs.index_, gs._problem, seeds.path(used[0]))
    motion, _ = assemble(lib2, tracks, ev.pieces, ev.placement, req)
    assert np.abs(motion.root_positions).max() == 0.0
    fixed, _ = assemble(_with_reference_root(library), tracks, ev.pieces, ev.placement, req)
    np.testing.assert_allclose(motion.global_positions(), fixed.global_positions(), atol=1e-8)


# -- the anytime search --------------------------------------------------------------------------


def test_search_is_anytime_improving_and_meets_the_constraints(graph: Graph) -> None:
    out = Collect()
    req = request()
    # bounded by rounds, not by time: the same work on a loaded machine (a time budget flaked)
    searcher(graph, 3).run(req, 60.0, out, lambda: False, max_rounds=6)
    best = [s for s in out.solutions if s.metrics["alternative"] == 0]
    assert len(best) >= 2
    scores = [s.score for s in best]
    assert all(b < a for a, b in itertools.pairwise(scores))
    final = best[-1]
    assert min(s.score for s in out.solutions) == final.score
    assert final.motion.num_frames == 240 and len(final.provenance) == 240
    errors = final.constraint_errors
    assert errors["length"]["frames"] == 0 and errors["length"]["satisfied"]
    assert errors["body[0]"]["position_cm"] < 0.1 and errors["body[1]"]["position_cm"] < 0.1
    assert errors["body[1]"]["heading_deg"] < 0.1
    assert set(final.terms) == {"continuity", "length", "body", "joint", "label", "obstacle", "shared"}
    assert final.score == pytest.approx(sum(final.terms.values()))
    # (how early the first solution comes is bench/graph.py's first_solution_ms, not a test)


def clip_sequence(s: Solution) -> tuple[str, ...]:
    """The clips of a solution's pieces, from its provenance (a piece starts wherever the source
    frame is not the next frame of the same clip)."""
    prov = s.provenance
    return tuple(
        c for i, (c, f) in enumerate(prov) if i == 0 or (c, f) != (prov[i - 1][0], prov[i - 1][1] + 1)
    )


def test_alternatives_are_distinct_and_after_the_best(graph: Graph) -> None:
    out = Collect()
    searcher(graph, 5).run(request(alternatives=4), 1.5, out, lambda: False)
    alts = [s for s in out.solutions if s.metrics["alternative"] > 0]
    assert len(alts) == 3
    best = [s for s in out.solutions if s.metrics["alternative"] == 0][-1]
    assert all(a.score >= best.score for a in alts)
    assert len({clip_sequence(s) for s in [best, *alts]}) == 4
    assert all(a.motion.num_frames == 240 for a in alts)
    assert all(a.constraint_errors["body[1]"]["position_cm"] < 0.1 for a in alts)


def test_same_seed_same_solutions(graph: Graph) -> None:
    runs = []
    for _ in range(2):
        out = Collect()
        searcher(graph, 11).run(request(seed=11), 60.0, out, lambda: False, max_rounds=3)
        runs.append([(s.score, s.provenance) for s in out.solutions])
    assert runs[0] == runs[1] and len(runs[0]) >= 2
    other = Collect()
    searcher(graph, 12).run(request(seed=12), 60.0, other, lambda: False, max_rounds=3)
    assert [(s.score, s.provenance) for s in other.solutions] != runs[0]


def test_cancel_stops_at_the_next_poll(graph: Graph) -> None:
    """Cancelled as soon as its first solution is out, the search stops at its next poll: at most
    the one emission under way follows, and no alternatives (an uncancelled run of this request
    emits them). No clock: the cancel is a function of the search's own output."""
    out = Collect()
    stopped = searcher(graph, 2).run(request(alternatives=2), 600.0, out, lambda: len(out.solutions) >= 1)
    assert stopped == Stopped.cancelled
    assert 1 <= len(out.solutions) <= 2
    assert all(s.metrics["alternative"] == 0 for s in out.solutions)


def test_budget_is_respected(graph: Graph, monkeypatch: pytest.MonkeyPatch) -> None:
    """The time cap cuts the search short, on a clock that advances 10 ms at every reading: the
    cap is spent after a fixed number of readings, whatever the machine's speed or load."""
    ticks = itertools.count(1)
    monkeypatch.setattr(engines_base, "CLOCK", lambda: next(ticks) * 0.01)
    gs, out = searcher(graph, 2), Collect()
    stopped = gs.run(request(alternatives=2), 0.6, out, lambda: False, max_rounds=4)
    # stopped before the 4 rounds it would run unhurried (it converges after about 35), with a
    # best solution and its alternatives
    assert stopped == Stopped.budget and next(ticks) > 60 and getattr(gs, "rounds_", 0) < 4
    assert out.solutions and out.solutions[0].metrics["alternative"] == 0


def test_hard_pose_constraints_hold(graph: Graph) -> None:
    req = request(
        frames=200,
        constraints=[
            {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
            {"type": "pose", "frame": 80, "clip": "left", "clip_frame": 40},
            {"type": "pose", "frame": 150, "clip": "right", "clip_frame": 110},
            {"type": "body", "frame": 199, "position": [1.0, 5.0]},
        ],
    )
    out = Collect()
    searcher(graph, 4).run(req, 60.0, out, lambda: False)
    assert out.solutions
    for s in out.solutions:
        assert s.provenance[80] == ("left", 40)
        assert s.provenance[150] == ("right", 110)
        assert s.constraint_errors["pose[0]"]["held"] and s.constraint_errors["pose[1]"]["held"]
        assert s.motion.num_frames == 200


def test_impossible_pose_constraints_are_reported(graph: Graph) -> None:
    req = request(
        frames=200,
        constraints=[
            {"type": "pose", "frame": 10, "clip": "left", "clip_frame": 40},
            {"type": "pose", "frame": 11, "clip": "right", "clip_frame": 100},
        ],
    )
    with pytest.raises(EngineError, match="pose constraints"):
        searcher(graph, 4).run(req, 60.0, Collect(), lambda: False)


def test_labels_and_obstacles_steer_the_search(graph: Graph) -> None:
    req = request(
        frames=150,
        constraints=[
            {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
            {"type": "label", "label": "slow", "start": 0, "end": 150},
            {"type": "obstacle", "disc": {"center": [0.0, 3.0], "radius": 0.8}},
        ],
    )
    out = Collect()
    searcher(graph, 6).run(req, 60.0, out, lambda: False)
    best = min(out.solutions, key=lambda s: s.score)
    errors = best.constraint_errors
    assert errors["obstacle[0]"]["frames"] == 0
    assert errors["label[0]"]["frames"] < 75  # mostly slow walking, around the disc


def test_joint_constraint_is_scored(graph: Graph) -> None:
    library, tree, tracks = graph
    index = GraphIndex(tree, tracks)
    req = request(
        frames=60,
        constraints=[
            {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
            {
                "type": "joint",
                "frame": 30,
                "joint": "head",
                "position": [0.0, 1.6, 1.2],
                "velocity": [0, 0, 1.2],
            },
        ],
    )
    prob = compile_problem(req, library, tracks)
    ev = evaluate(index, prob, Path(0, 0))
    motion, prov = assemble(library, tracks, ev.pieces, ev.placement, req, prob)
    errors = measured(motion, prov, prob, library)
    # the straight walk covers 1.2 m in 1 s: head near [0, 1.6, 1.2], moving at ~1.2 m/s along +Z;
    # assembly spreads the head's floor error over frames 1-30, so it is met exactly
    assert errors["joint[0]"]["position_cm"] < 15
    assert errors["joint[0]"]["velocity_cm_s"] < 80  # the synthetic head jitters
    head = motion.global_positions()[:, motion.skeleton.index("head")]
    assert np.linalg.norm(head[30, [0, 2]] - [0.0, 1.2]) < 1e-6
    # the score charges that floor correction, the height and the velocity, from the motion as
    # played before the correction (no smoothing on a path without cuts)
    plain = request(frames=60, constraints=req.model_dump()["constraints"][:1])
    raw, _ = assemble(library, tracks, ev.pieces, ev.placement, plain)
    head = raw.global_positions()[:, raw.skeleton.index("head")]
    pos, vel = head[30], (head[31] - head[29]) * 15.0
    expected = np.sum((pos - [0.0, 1.6, 1.2]) ** 2) / 0.09 + np.sum((vel - [0, 0, 1.2]) ** 2) / 0.09
    assert ev.terms["joint"] == pytest.approx(expected, rel=1e-6)


def test_batch_scores_match_single_evaluations(graph: Graph) -> None:
    gs = searcher(graph)
    req = request()
    prime(gs, req)
    batch = gs._random_seeds(np.random.default_rng(9), 16)
    s = score_batch(gs.index_, gs._problem, batch)
    for i in range(batch.size):
        assert evaluate(gs.index_, gs._problem, batch.path(i)).score == pytest.approx(s.total[i], rel=1e-12)


# -- real data, end to end (needs ../shared/data and the build half) ---------------------------

BANDAI = FsPath(__file__).resolve().parents[3] / "shared" / "data" / "bandai-namco" / "dataset-2"


@pytest.mark.skipif(not BANDAI.exists(), reason="needs ../shared/data/bandai-namco")
def test_bandai_end_to_end() -> None:
    build = pytest.importorskip("engines.graph.build")
    from engines.graph.engine import GraphEngine
    from engines.library import ClipInput, build_library, library_to_arrays
    from engines.registry import parse_database_spec, parse_job_request

    files: list[str] = []
    for kind in ("walk", "walk-turn-left", "walk-turn-right"):
        files += sorted(glob.glob(str(BANDAI / f"dataset-2_{kind}_normal_*.bvh")))[-4:]
    spec = parse_database_spec({"kind": "graph", "clips": [{"bvh": f} for f in files]})
    library = build_library([ClipInput(FsPath(f).stem, FsPath(f).read_bytes()) for f in files], spec.fps)
    arrays = build.build_graph(spec, library, Collect(), lambda: False)
    arrays.update(library_to_arrays(library))
    engine = GraphEngine(library, arrays)
    req = parse_job_request(
        {
            "engine": "graph",
            "frames": 300,
            "seed": 2,
            "alternatives": 2,
            "constraints": [
                {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
                {"type": "body", "frame": 299, "position": [3.0, 5.0], "heading_deg": -90.0},
            ],
        }
    )
    out = Collect()
    engine.search(req, Run(2.0, emit=out))
    best = min(out.solutions, key=lambda s: s.score)
    m = best.motion
    assert m.num_frames == 300
    pos = m.global_positions() * m.metres_per_unit
    names = [n.lower() for n in m.skeleton.names]
    hip, lt, rt = names.index("hips"), names.index("upperleg_l"), names.index("upperleg_r")
    for f, goal, head in ((0, [0.0, 0.0], 0.0), (299, [3.0, 5.0], -90.0)):
        assert np.linalg.norm(pos[f, hip, [0, 2]] - goal) < 0.05
        fwd = np.cross(pos[f, lt] - pos[f, rt], [0.0, 1.0, 0.0])
        assert abs((np.degrees(np.arctan2(fwd[0], fwd[2])) - head + 180) % 360 - 180) < 5.0


def test_seconds_times_and_no_body_constraint(graph: Graph) -> None:
    body = {
        "engine": "graph",
        "seconds": 5.0,
        "seed": 1,
        "smoothing_frames": 0,
        "constraints": [{"type": "body", "time_s": 4.9, "position": [1.0, 2.0]}],
    }
    out = Collect()
    searcher(graph, 1).run(GraphRequest.model_validate(body), 0.5, out, lambda: False)
    best = min(out.solutions, key=lambda s: s.score)
    assert best.motion.num_frames == 150
    assert best.constraint_errors["body[0]"]["frame"] == 147
    assert best.constraint_errors["body[0]"]["position_cm"] < 0.1
    # nothing to meet: the motion starts at the origin facing +Z
    out = Collect()
    searcher(graph, 1).run(
        request(frames=90, constraints=[], alternatives=1, smoothing_frames=0), 0.3, out, lambda: False
    )
    xz, yaw = body_frames(out.solutions[-1].motion)
    np.testing.assert_allclose(xz[0], [0.0, 0.0], atol=1e-6)
    assert abs(yaw[0]) < 1e-6


def test_loop_option_closes_the_clip_and_is_reported(graph: Graph) -> None:
    out = Collect()
    searcher(graph, 3).run(request(loop=True, alternatives=1), 0.6, out, lambda: False)
    final = out.solutions[-1]
    loop = final.constraint_errors["loop"]
    assert loop["satisfied"] and loop["pose_cm"] < 1.0, loop
    plain = Collect()
    searcher(graph, 3).run(request(alternatives=1), 0.6, plain, lambda: False)
    assert "loop" not in plain.solutions[-1].constraint_errors
