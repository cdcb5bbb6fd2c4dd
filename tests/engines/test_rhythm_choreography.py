"""Movement-graph edits by choreographic rules (KPS03 Sec. 4.3) on real salsa motion capture:
the graph as described, groups named by clip spans, the rules, and synthesis obeying the edits."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order

from engines.base import EngineError
from engines.library import library_from_arrays
from engines.rhythm.choreography import (
    GraphEditError,
    apply_edits,
    edited_arrays,
    group_of_span,
    movement_graph,
    resolve_edits,
)
from engines.rhythm.reach import describe as describe_graph
from engines.rhythm.reach import start_only_groups, unreachable_groups
from engines.rhythm.synth import draw_probabilities
from schemas.movement_graph import ClipSpan, GraphEdits, ResolvedEdit
from tests.engines.rhythm_salsa import SAMPLES, group_walks, salsa_arrays, transition_counts

SEEDS = range(40)
SALSA_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "cmu-salsa"


@pytest.fixture(scope="module")
def arrays() -> dict[str, Any]:
    return salsa_arrays()


@pytest.fixture(scope="module")
def learned_walks(arrays: dict[str, Any]) -> list[list[int]]:
    return group_walks(arrays, SEEDS)


def safe_cut(p: np.ndarray, a: int) -> int:
    """A transition out of ``a`` whose target other groups also reach (cutting it breaks no rule)."""
    others = (p > 0) & ~np.eye(p.shape[0], dtype=bool)  # transitions between two different groups
    return next(int(b) for b in np.flatnonzero(p[a] > 0) if others[:, b].sum() >= 2 and b != a)


def edits(*items: dict[str, Any]) -> GraphEdits:
    return GraphEdits.model_validate({"edits": list(items)})


def test_graph_describes_what_synthesis_walks(arrays: dict[str, Any]) -> None:
    g = movement_graph(arrays, "db", 0.5)
    p = np.asarray(arrays["rhythm.p"])
    k = p.shape[0]
    assert [x.id for x in g.groups] == list(range(k))
    assert sum(x.size for x in g.groups) == np.asarray(arrays["rhythm.labels"]).size
    assert len(g.transitions) == int((p > 0).sum()) and all(t.learned for t in g.transitions)
    draw = draw_probabilities(p, np.asarray(arrays["rhythm.clarity"]), np.asarray(arrays["rhythm.labels"]))
    rows = np.zeros(k)
    for t in g.transitions:
        assert t.probability == pytest.approx(draw[t.source, t.target], abs=1e-6)
        assert t.kinematic == pytest.approx(arrays["rhythm.kinematic"][t.source, t.target], abs=1e-6)
        assert t.behavioural == pytest.approx(arrays["rhythm.behavioural"][t.source, t.target], abs=1e-6)
        rows[t.source] += t.probability
    np.testing.assert_allclose(rows, 1.0, atol=1e-4)
    frames = dict(zip(arrays["library.names"], arrays["library.frame_counts"], strict=True))
    lib = library_from_arrays(arrays)
    for grp in g.groups:
        r = grp.representative
        assert r.clip in SAMPLES and not r.mirrored
        assert 0 <= r.start_frame < r.end_frame < frames[r.clip]
        assert r.start_s == pytest.approx(r.start_frame / 30, abs=0.02)
        assert r.start_frame <= grp.pose_frame <= r.end_frame
        pose = np.asarray(grp.pose)
        assert pose.shape == (len(g.joints), 3)
        # the thumbnail is the source clip's pose at that frame (heights agree; the floor position
        # and heading are the movement's own)
        src = lib.clip(r.clip).global_positions()[grp.pose_frame]
        assert np.abs(pose[:, 1] - src[:, 1]).max() < 0.05
        # the representative span names its own group back
        span = ClipSpan(clip=r.clip, frames=(r.start_frame + 2, r.end_frame - 2))
        assert group_of_span(span, arrays) == grp.id
    assert g.strongly_connected and g.derived_from is None


def test_clip_spans_name_the_group_of_the_movement_that_holds_them(arrays: dict[str, Any]) -> None:
    names = [str(n) for n in arrays["library.names"]]
    src = np.asarray(arrays["rhythm.src_frames"])
    labels = np.asarray(arrays["rhythm.labels"])
    for m in range(labels.size):
        clip = names[int(arrays["rhythm.src_clip"][m])]
        s, e = float(src[m, 0]), float(src[m, -1])
        mid = int((s + e) / 2)
        assert group_of_span(ClipSpan(clip=clip, frames=(mid, mid)), arrays) == labels[m]
        assert group_of_span(ClipSpan(clip=clip, seconds=(mid / 30, mid / 30)), arrays) == labels[m]
        assert group_of_span(ClipSpan(clip=clip, frames=(int(s) + 1, int(e))), arrays) == labels[m]
    with pytest.raises(EngineError, match="no clip 'salsa'"):
        group_of_span(ClipSpan(clip="salsa", frames=(0, 10)), arrays)
    with pytest.raises(EngineError, match="fall in none of its basic movements"):
        group_of_span(ClipSpan(clip="salsa-leader-02", seconds=(1000, 1001)), arrays)


def test_a_cut_transition_never_appears(arrays: dict[str, Any], learned_walks: list[list[int]]) -> None:
    k = np.asarray(arrays["rhythm.p"]).shape[0]
    before = transition_counts(learned_walks, k)
    # the three transitions the learned graph takes most often (that the rules let go together)
    order = np.dstack(np.unravel_index(np.argsort(before, axis=None)[::-1], before.shape))[0]
    top: list[tuple[int, int]] = []
    for a, b in order:
        trial = [ResolvedEdit(op="cut", source=int(x), target=int(y)) for x, y in [*top, (a, b)]]
        try:
            apply_edits(np.asarray(arrays["rhythm.p"]), trial)
        except GraphEditError:
            continue
        top.append((int(a), int(b)))
        if len(top) == 3:
            break
    cut = [{"op": "cut", "source": a, "target": b} for a, b in top]
    assert all(before[a, b] > 0 for a, b in top)  # they were used before the edit
    derived = edited_arrays(arrays, resolve_edits(edits(*cut).edits, arrays))
    after = transition_counts(group_walks(derived, SEEDS), k)
    assert all(after[a, b] == 0 for a, b in top)
    assert after.sum() == before.sum()  # as many movements as before: the dances go on


def test_an_added_transition_appears(arrays: dict[str, Any], learned_walks: list[list[int]]) -> None:
    p = np.asarray(arrays["rhythm.p"])
    k = p.shape[0]
    before = transition_counts(learned_walks, k)
    visits = before.sum(axis=1)
    # the most visited group's missing transitions: the learned graph never takes them
    a = int(np.argmax(visits))
    missing = [int(b) for b in np.flatnonzero(p[a] == 0)]
    assert missing and all(before[a, b] == 0 for b in missing)
    derived = edited_arrays(arrays, [ResolvedEdit(op="connect", source=a, target=b) for b in missing])
    after = transition_counts(group_walks(derived, SEEDS), k)
    assert all(after[a, b] > 0 for b in missing), after[a]


def test_weights_shift_frequencies(arrays: dict[str, Any], learned_walks: list[list[int]]) -> None:
    p = np.asarray(arrays["rhythm.p"])
    k = p.shape[0]
    before = transition_counts(learned_walks, k)
    a = int(np.argmax(before.sum(axis=1)))
    b = int(np.flatnonzero(p[a] > 0)[np.argmin(p[a][p[a] > 0])])  # its least likely transition
    up = edited_arrays(arrays, [ResolvedEdit(op="weight", source=a, target=b, weight=10.0)])
    assert up["rhythm.p"][a, b] == pytest.approx(10 * p[a, b] / (1 + 9 * p[a, b]))
    after = transition_counts(group_walks(up, SEEDS), k)
    share_before = before[a, b] / before[a].sum()
    share_after = after[a, b] / after[a].sum()
    assert share_after > share_before + 0.2, (share_before, share_after)


def test_edits_apply_in_order_and_rows_stay_distributions(arrays: dict[str, Any]) -> None:
    p = np.asarray(arrays["rhythm.p"])
    a = 0
    gone = safe_cut(p, a)
    miss = int(np.flatnonzero(p[a] == 0)[0])
    out = apply_edits(
        p,
        [
            ResolvedEdit(op="cut", source=a, target=gone),
            ResolvedEdit(op="connect", source=a, target=miss, weight=2.0),
        ],
    )
    np.testing.assert_allclose(out.sum(axis=1), 1.0)
    assert out[a, gone] == 0 and out[a, miss] > 0
    rest = np.flatnonzero((p[a] > 0) & (np.arange(p.shape[0]) != gone))
    np.testing.assert_allclose(out[a, miss] / out[a, rest[0]], 2 * p[a, rest].mean() / p[a, rest[0]])
    np.testing.assert_array_equal(out[1:], p[1:])  # other rows untouched


@pytest.mark.parametrize(
    ("items", "index", "problem", "message"),
    [
        ([{"op": "cut", "source": 0, "target": 99}], 0, "unknown_group", "no group 99"),
        (
            [{"op": "weight", "source": {"clip": "nope", "frames": [0, 5]}, "target": 1, "weight": 2}],
            0,
            "bad_span",
            "no clip 'nope'",
        ),
        (
            [{"op": "cut", "source": 0, "target": {"clip": "salsa-leader-02", "seconds": [900, 901]}}],
            0,
            "bad_span",
            "fall in none",
        ),
    ],
)
def test_edits_naming_no_group_are_refused(
    arrays: dict[str, Any], items: list[dict[str, Any]], index: int, problem: str, message: str
) -> None:
    with pytest.raises(GraphEditError, match=message) as info:
        resolve_edits(edits(*items).edits, arrays)
    assert info.value.index == index and info.value.details["problem"] == problem


def test_rules_dead_end_unreachable_and_existence(arrays: dict[str, Any]) -> None:
    p = np.asarray(arrays["rhythm.p"])
    k = p.shape[0]
    indegree = ((p > 0) & ~np.eye(k, dtype=bool)).sum(axis=0)  # from other groups
    # a group whose targets other groups reach too (cutting its transitions strands none of them)
    a = next(x for x in range(k) if all(indegree[b] >= 2 for b in np.flatnonzero(p[x] > 0) if b != x))
    out_a = [int(b) for b in np.flatnonzero(p[a] > 0)]
    dead = [ResolvedEdit(op="cut", source=a, target=b) for b in out_a]
    with pytest.raises(
        GraphEditError, match=f"cuts the last transition out of group {a}: a dead end"
    ) as info:
        apply_edits(p, dead)
    assert info.value.index == len(out_a) - 1 and info.value.details["problem"] == "dead_end"
    # connecting it elsewhere first keeps a way out (to itself only would close it off)
    elsewhere = int(np.flatnonzero((p[a] == 0) & (np.arange(k) != a))[0])
    if p[a, a] == 0:
        with pytest.raises(GraphEditError, match="never reaches"):
            apply_edits(p, [ResolvedEdit(op="connect", source=a, target=a), *dead])
    ok = apply_edits(p, [ResolvedEdit(op="connect", source=a, target=elsewhere), *dead])
    assert np.flatnonzero(ok[a] > 0).tolist() == [elsewhere]
    # every transition into a group cut: nothing reaches it again
    g = int(np.argmax((p > 0).sum(axis=0)))
    into = [ResolvedEdit(op="cut", source=x, target=g) for x in range(k) if x != g and p[x, g] > 0]
    with pytest.raises(GraphEditError, match="never reaches groups") as info:
        apply_edits(p, into)
    assert info.value.details["problem"] == "unreachable"
    assert g in info.value.details["unreachable_groups"]  # (and any group only it leads to)
    assert info.value.index == len(into) - 1
    b = int(np.flatnonzero(p[1] == 0)[0])
    with pytest.raises(GraphEditError, match="no transition 1 -> .* to cut"):
        apply_edits(p, [ResolvedEdit(op="cut", source=1, target=b)])
    with pytest.raises(GraphEditError, match="connect it first"):
        apply_edits(p, [ResolvedEdit(op="weight", source=1, target=b, weight=3.0)])
    c = int(np.flatnonzero(p[1] > 0)[0])
    tiny = [ResolvedEdit(op="weight", source=1, target=c, weight=1e-6)] * 50
    with pytest.raises(GraphEditError, match="underflow") as info:
        apply_edits(p, tiny)
    assert info.value.index == 41
    huge = [ResolvedEdit(op="weight", source=1, target=c, weight=1e6)] * 60
    with pytest.raises(GraphEditError, match="overflow"):
        apply_edits(p, huge)
    with pytest.raises(GraphEditError, match="exists already"):
        apply_edits(p, [ResolvedEdit(op="connect", source=1, target=c)])


def test_schema_refuses_bad_weights_and_spans() -> None:
    from pydantic import ValidationError

    for item in (
        {"op": "weight", "source": 0, "target": 1, "weight": 0},
        {"op": "weight", "source": 0, "target": 1, "weight": -2},
        {"op": "weight", "source": 0, "target": 1},
        {"op": "cut", "source": 0, "target": 1, "weight": 2},
        {"op": "cut", "source": {"clip": "a"}, "target": 1},
        {"op": "cut", "source": {"clip": "a", "frames": [5, 2]}, "target": 1},
        {"op": "cut", "source": {"clip": "a", "frames": [1, 2], "seconds": [0, 1]}, "target": 1},
        {"op": "join", "source": 0, "target": 1},
    ):
        with pytest.raises(ValidationError):
            edits(item)
    with pytest.raises(ValidationError):
        GraphEdits.model_validate_json(
            '{"edits": [{"op": "weight", "source": 0, "target": 1, "weight": Infinity}]}'
        )
    with pytest.raises(ValidationError):
        GraphEdits.model_validate({"edits": []})


def test_derived_arrays_keep_everything_but_the_graph(arrays: dict[str, Any]) -> None:
    p = np.array(arrays["rhythm.p"], copy=True)
    b = safe_cut(p, 0)
    out = edited_arrays(arrays, [ResolvedEdit(op="cut", source=0, target=b)])
    np.testing.assert_array_equal(arrays["rhythm.p"], p)  # the parent's arrays are untouched
    np.testing.assert_array_equal(out["rhythm.learned_p"], p)
    assert set(out) == set(arrays) | {"rhythm.learned_p"}
    for key in arrays:
        if key != "rhythm.p":
            np.testing.assert_array_equal(out[key], arrays[key])
    g = movement_graph(out, "derived")
    assert not any(t.source == 0 and t.target == b for t in g.transitions)
    # a derivation of a derivation still knows the learned graph
    again = edited_arrays(out, [ResolvedEdit(op="connect", source=0, target=b)])
    np.testing.assert_array_equal(again["rhythm.learned_p"], p)
    added = [t for t in movement_graph(again, "d2").transitions if not t.learned]
    assert added == []  # connecting back a learned transition is not an addition


def reach_of(p: np.ndarray) -> np.ndarray:
    """``(K, K)`` j reachable from i (in zero or more transitions), by breadth-first search: a
    reference independent of :mod:`engines.rhythm.reach`."""
    k = p.shape[0]
    out = np.zeros((k, k), dtype=bool)
    for i in range(k):
        out[i, breadth_first_order(csr_matrix(p > 0), i, directed=True, return_predecessors=False)] = True
    return out


# groups 0, 1, 2 lead to each other; 3 only starts dances (nothing leads to it); 4 is no start group
# and only 3 leads to it
NOT_STRONG = np.array(
    [
        [0.4, 0.3, 0.3, 0.0, 0.0],
        [0.5, 0.0, 0.5, 0.0, 0.0],
        [0.2, 0.8, 0.0, 0.0, 0.0],
        [0.6, 0.0, 0.0, 0.0, 0.4],
        [0.0, 0.0, 1.0, 0.0, 0.0],
    ]
)


def test_edits_on_a_graph_not_strongly_connected_are_judged_by_what_they_change() -> None:
    p = NOT_STRONG
    start = np.array([0.3, 0.3, 0.2, 0.2, 0.0])
    assert start_only_groups(p > 0, start) == [3] and unreachable_groups(p > 0, start) == []
    assert start_only_groups(p > 0, np.array([0.5, 0.5, 0, 0, 0])) == []
    assert unreachable_groups(p > 0, np.array([0.5, 0.5, 0, 0, 0])) == [3, 4]
    assert "start-only groups [3]" in describe_graph(p, start)
    # cuts and weights that keep every group as reachable as before are accepted
    for ok in (
        [ResolvedEdit(op="cut", source=0, target=0)],
        [ResolvedEdit(op="cut", source=0, target=1)],  # 0 -> 2 -> 1 is left
        [ResolvedEdit(op="cut", source=3, target=0)],  # 3 -> 4 -> 2 -> 0 is left
        [ResolvedEdit(op="weight", source=1, target=2, weight=3.0)],
    ):
        out = apply_edits(p, ok)
        np.testing.assert_array_equal(reach_of(out), reach_of(p))
        np.testing.assert_allclose(out.sum(axis=1), 1.0)
        e = ok[0]
        assert (out[e.source, e.target] == 0) == (e.op == "cut")
    # a dead end is refused by name
    with pytest.raises(GraphEditError, match="cuts the last transition out of group 4: a dead end") as info:
        apply_edits(p, [ResolvedEdit(op="cut", source=4, target=2)])
    assert info.value.details["problem"] == "dead_end" and info.value.details["groups"] == [4]
    # a cut that loses a way between groups is refused, naming the groups and the edit
    with pytest.raises(GraphEditError, match=r"edit 1 \(cut 2 -> 1\) makes groups \[1\] unreachable") as info:
        apply_edits(
            p, [ResolvedEdit(op="cut", source=0, target=1), ResolvedEdit(op="cut", source=2, target=1)]
        )
    assert info.value.details["unreachable_groups"] == [1] and info.value.details["from_groups"] == [
        0,
        2,
        3,
        4,
    ]
    with pytest.raises(GraphEditError, match=r"makes groups \[4\] unreachable from groups \[3\]"):
        apply_edits(p, [ResolvedEdit(op="cut", source=3, target=4)])
    # a connection lets a cut through that alone would lose a way
    out = apply_edits(
        p, [ResolvedEdit(op="connect", source=0, target=4), ResolvedEdit(op="cut", source=3, target=4)]
    )
    assert out[3, 4] == 0 and out[0, 4] > 0 and reach_of(out)[0, 4]


def test_a_closed_part_may_stay_but_no_new_one_is_made() -> None:
    # groups 0 and 1 lead to each other and to 2; 2 only to itself: a dance that reaches 2 stays there
    p = np.array([[0.5, 0.3, 0.2], [0.6, 0.0, 0.4], [0.0, 0.0, 1.0]])
    out = apply_edits(p, [ResolvedEdit(op="weight", source=0, target=1, weight=2.0)])
    np.testing.assert_allclose(out[0], np.array([0.5, 0.6, 0.2]) / 1.3)
    with pytest.raises(GraphEditError, match="a dead end"):
        apply_edits(p, [ResolvedEdit(op="cut", source=2, target=2)])
    with pytest.raises(GraphEditError, match=r"makes groups \[2\] unreachable from groups \[0, 1\]"):
        apply_edits(
            p, [ResolvedEdit(op="cut", source=0, target=2), ResolvedEdit(op="cut", source=1, target=2)]
        )
    fixed = apply_edits(p, [ResolvedEdit(op="connect", source=2, target=0)])
    np.testing.assert_allclose(fixed[2], [0.5, 0.0, 0.5])  # as likely as the row's average transition
    assert reach_of(fixed).all()


def keeps_reach(p: np.ndarray, a: int, b: int) -> bool:
    """Cutting ``a -> b`` leaves every group reachable from every group it was reachable from."""
    cut = p.copy()
    cut[a, b] = 0.0
    return bool(np.array_equal(reach_of(cut), reach_of(p)))


OTHER_LEADERS = ("03", "09", "11", "13", "15")
"""Five salsa leaders of ../shared/data no bundled database holds: with ``edge_threshold`` 0.08 and
4 beats per movement their learned graph is not strongly connected (a start-only group)."""


@pytest.fixture(scope="module")
def other_leaders() -> dict[str, Any]:
    from engines.library import ClipInput
    from engines.registry import parse_database_spec
    from workers.execute import build_database_bytes
    from workers.store import load_npz

    files = [SALSA_DATA / f"60_{n}_scaled.bvh" for n in OTHER_LEADERS]
    if not all(f.is_file() for f in files):
        pytest.skip(f"shared data not found: {SALSA_DATA}")
    spec = {
        "kind": "rhythm",
        "clips": [{"bvh": f.name, "name": f"L{n}"} for f, n in zip(files, OTHER_LEADERS, strict=True)],
        "fps": 30,
        "beats_per_movement": 4,
        "edge_threshold": 0.08,
    }
    clips = [ClipInput(f"L{n}", f.read_bytes()) for f, n in zip(files, OTHER_LEADERS, strict=True)]
    messages: list[str] = []
    data, _ = build_database_bytes(
        parse_database_spec(spec),
        clips,
        lambda _t, data: messages.append(str(data.get("message", ""))),
        lambda: False,
    )
    return {"arrays": load_npz(data), "messages": messages}


def test_real_graph_not_strongly_connected_takes_a_cut_that_keeps_reach(
    other_leaders: dict[str, Any],
) -> None:
    arrays = other_leaders["arrays"]
    p = np.asarray(arrays["rhythm.p"])
    k = p.shape[0]
    g = movement_graph(arrays, "others")
    reach = reach_of(p)
    assert not g.strongly_connected and not reach.all()
    into = (p > 0) & ~np.eye(k, dtype=bool)
    assert g.start_only_groups and all(not into[:, x].any() for x in g.start_only_groups)
    said = [m for m in other_leaders["messages"] if m.startswith("movement graph:")]
    assert said and f"start-only groups {g.start_only_groups}" in said[0] and "no dead end" in said[0]
    # the most taken transition whose cut keeps every group as reachable as before
    walks = group_walks(arrays, range(12))
    counts = transition_counts(walks, k)
    keeps = [
        (int(a), int(b)) for a, b in zip(*np.nonzero(p > 0), strict=True) if a != b and keeps_reach(p, a, b)
    ]
    a, b = max(keeps, key=lambda t: counts[t])
    assert counts[a, b] > 0
    derived = edited_arrays(arrays, [ResolvedEdit(op="cut", source=a, target=b)])
    assert movement_graph(derived, "cut").start_only_groups == g.start_only_groups
    after = transition_counts(group_walks(derived, range(12)), k)
    assert after[a, b] == 0 and after.sum() == counts.sum()
    # a dead end is still refused, naming the group
    out_a = [ResolvedEdit(op="cut", source=a, target=int(x)) for x in np.flatnonzero(p[a] > 0)]
    with pytest.raises(GraphEditError, match=f"cuts the last transition out of group {a}: a dead end"):
        apply_edits(p, out_a)


def test_reported_probabilities_are_what_dances_take(
    arrays: dict[str, Any], learned_walks: list[list[int]]
) -> None:
    """The graph's probabilities include the beat-clarity preference: the transitions the dances
    take out of their most visited group follow them (total variation within sampling noise)."""
    g = movement_graph(arrays, "db", 0.5)
    k = len(g.groups)
    counts = transition_counts(learned_walks, k)
    a = int(np.argmax(counts.sum(axis=1)))
    reported = np.zeros(k)
    for t in g.transitions:
        if t.source == a:
            reported[t.target] = t.probability
    observed = counts[a] / counts[a].sum()
    assert counts[a].sum() >= 100
    assert 0.5 * np.abs(observed - reported).sum() < 0.12, (observed, reported)
