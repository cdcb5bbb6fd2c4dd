"""Foot-skate cleanup in graph assembly: propagated source contacts, constraints kept."""

from __future__ import annotations

import numpy as np

from engines.graph.assemble import assemble, body_frames, library_contacts, propagated_contacts
from engines.graph.build import build_graph
from engines.graph.engine import GraphEngine
from engines.graph.model import FootContacts
from engines.graph.score import Evaluation, compile_problem, evaluate
from engines.graph.search import GraphSearch
from engines.graph.tracks import foot_contacts
from engines.library import MotionLibrary
from motion.contacts import detect_contacts
from motion.metrics import foot_slip
from schemas.graph import GraphRequest

from .test_graph_build import spec
from .test_graph_search import Collect, Graph, graph, prime, request, searcher  # noqa: F401


def gait_contacts(library: MotionLibrary) -> FootContacts:
    """Each foot planted 6 frames of every 15 (the synthetic walkers' feet always slide, so
    detection finds none; the cleanup pins whatever the contacts say)."""
    sk = library.motions[0].skeleton
    joints = np.array([sk.index("lFoot"), sk.index("rFoot")], dtype=np.int64)
    flags = []
    for m in library.motions:
        f = np.arange(m.num_frames)
        flags.append(np.stack((f % 15 < 6, (f + 7) % 15 < 6), axis=1))
    return FootContacts(joints, np.concatenate(flags))


def _cut_path(graph: Graph, req: GraphRequest) -> tuple[GraphSearch, Evaluation]:  # noqa: F811
    """A seed path with several cuts and its evaluation."""
    gs = searcher(graph)
    prime(gs, req)
    seeds = gs._random_seeds(np.random.default_rng(7), 32)
    n = [len(seeds.path(i).edges) for i in range(seeds.size)]
    ev = evaluate(gs.index_, gs._problem, seeds.path(int(np.argmax(n))))
    assert ev.pieces.clip.size >= 3
    return gs, ev


def test_cleanup_pins_feet_and_keeps_body_constraints(graph: Graph) -> None:  # noqa: F811
    library, _, tracks = graph
    req = request()
    gs, ev = _cut_path(graph, req)
    contacts = gait_contacts(library)
    raw, prov = assemble(library, tracks, ev.pieces, ev.placement, req, feet=False)
    clean, prov2 = assemble(library, tracks, ev.pieces, ev.placement, req, contacts=contacts)
    assert prov == prov2 and clean.num_frames == raw.num_frames
    np.testing.assert_array_equal(clean.root_positions, raw.root_positions)
    xz0, yaw0 = body_frames(raw)
    xz1, yaw1 = body_frames(clean)
    np.testing.assert_allclose(xz1, xz0, atol=1e-12)  # the hips do not move: body constraints hold
    np.testing.assert_allclose(yaw1, yaw0, atol=1e-12)
    np.testing.assert_allclose(xz1[239], [2.0, 4.0], atol=1e-6)
    joints, flags = propagated_contacts(contacts, tracks, *ev.pieces.source())
    assert flags.shape == (240, joints.size) and flags.any()
    before = foot_slip(raw, contacts=flags, joints=joints)
    after = foot_slip(clean, contacts=flags, joints=joints)
    assert after < 0.2 * before
    # only leg joints changed
    moved = np.flatnonzero(np.abs(clean.rotations - raw.rotations).max(axis=(0, 2)) > 0)
    names = {clean.skeleton.names[j] for j in moved}
    assert names and names <= {"lThigh", "lShin", "lFoot", "rThigh", "rShin", "rFoot"}


def test_joint_constraint_on_a_foot_is_left_alone(graph: Graph) -> None:  # noqa: F811
    library, _, tracks = graph
    req = request(
        constraints=[
            {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
            {"type": "body", "frame": 239, "position": [2.0, 4.0], "heading_deg": 60.0},
            {"type": "joint", "frame": 120, "joint": "lFoot", "position": [1.0, 0.1, 2.0]},
        ]
    )
    gs, ev = _cut_path(graph, req)
    problem = compile_problem(req, library, tracks)
    raw, _ = assemble(library, tracks, ev.pieces, ev.placement, req, problem, feet=False)
    clean, _ = assemble(
        library, tracks, ev.pieces, ev.placement, req, problem, contacts=gait_contacts(library)
    )
    foot = clean.skeleton.index("lFoot")
    p0, p1 = raw.global_positions(), clean.global_positions()
    np.testing.assert_allclose(p1[120, foot], p0[120, foot], atol=1e-12)
    # the other frames are still cleaned
    assert np.abs(p1 - p0).max() > 1e-4


def test_build_stores_contacts_and_engine_uses_them(graph: Graph) -> None:  # noqa: F811
    library, _, _ = graph
    arrays = build_graph(spec(), library, Collect(), lambda: False)
    stored = FootContacts.from_arrays(arrays)
    assert stored is not None
    fresh = foot_contacts(library)
    np.testing.assert_array_equal(stored.joints, fresh.joints)
    np.testing.assert_array_equal(stored.flags, fresh.flags)
    n = sum(m.num_frames for m in library.motions)
    assert stored.flags.shape == (n, stored.joints.size) and stored.flags.dtype == bool
    first = library.motions[0]
    np.testing.assert_array_equal(stored.flags[: first.num_frames], detect_contacts(first, stored.joints)[1])
    engine = GraphEngine(library, arrays)
    np.testing.assert_array_equal(engine.contacts.flags, stored.flags)
    # databases built before contacts were stored: computed at load
    old = {k: v for k, v in arrays.items() if not k.startswith("graph.contacts.")}
    assert FootContacts.from_arrays(old) is None
    np.testing.assert_array_equal(GraphEngine(library, old).contacts.flags, stored.flags)
    # the library is also cached for callers without the stored contacts
    assert library_contacts(library) is library_contacts(library)
    np.testing.assert_array_equal(library_contacts(library).flags, stored.flags)
    assert engine.tree.size > 0


def test_search_solutions_are_cleaned_with_the_given_contacts(graph: Graph) -> None:  # noqa: F811
    """The search does not depend on the contacts (same seed and rounds, same path); only the
    assembly does: no contact, no change."""
    library, _, tracks = graph
    gait = gait_contacts(library)
    runs = {}
    for name, contacts in (("gait", gait), ("none", FootContacts(gait.joints, gait.flags & False))):
        out = Collect()
        searcher(graph, 3, contacts=contacts).run(
            request(alternatives=1), 60.0, out, lambda: False, max_rounds=3
        )
        runs[name] = out.solutions[-1]
    assert runs["gait"].provenance == runs["none"].provenance
    prov = runs["gait"].provenance
    clips = np.array([library.index(c) for c, _ in prov])
    frames = np.array([f for _, f in prov])
    joints, flags = propagated_contacts(gait, tracks, clips, frames)
    assert flags.any()
    cleaned = foot_slip(runs["gait"].motion, contacts=flags, joints=joints)
    raw = foot_slip(runs["none"].motion, contacts=flags, joints=joints)
    assert cleaned < 0.3 * raw


def test_request_can_turn_the_cleanup_off(graph: Graph) -> None:  # noqa: F811
    """``footskate: false`` assembles the same path without pinning (as with no contacts)."""
    library, _, tracks = graph
    gait = gait_contacts(library)
    runs = {}
    for off in (False, True):
        out = Collect()
        searcher(graph, 3, contacts=gait).run(
            request(alternatives=1, footskate=not off), 60.0, out, lambda: False, max_rounds=3
        )
        runs[off] = out.solutions[-1]
    assert runs[False].provenance == runs[True].provenance
    prov = runs[True].provenance
    clips = np.array([library.index(c) for c, _ in prov])
    joints, flags = propagated_contacts(gait, tracks, clips, np.array([f for _, f in prov]))
    assert foot_slip(runs[False].motion, contacts=flags, joints=joints) < 0.3 * foot_slip(
        runs[True].motion, contacts=flags, joints=joints
    )
