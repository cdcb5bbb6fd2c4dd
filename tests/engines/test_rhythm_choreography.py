"""Movement-graph edits by choreographic rules (KPS03 Sec. 4.3) on real salsa motion capture:
the graph as described, groups named by clip spans, the rules, and synthesis obeying the edits."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

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
from engines.rhythm.synth import draw_probabilities
from schemas.rhythm_graph import ClipSpan, GraphEdits, ResolvedEdit
from tests.engines.rhythm_salsa import SAMPLES, group_walks, salsa_arrays, transition_counts

SEEDS = range(40)


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


def test_a_learned_graph_that_is_not_strongly_connected_must_be_fixed_by_the_edits() -> None:
    # groups 0 and 1 lead to each other and to 2; 2 only to itself: a dance that reaches 2 stays there
    p = np.array([[0.5, 0.3, 0.2], [0.6, 0.0, 0.4], [0.0, 0.0, 1.0]])
    with pytest.raises(GraphEditError, match=r"groups \[2\] have no transition to the other groups") as info:
        apply_edits(p, [ResolvedEdit(op="weight", source=0, target=1, weight=2.0)])
    assert info.value.index is None and info.value.details["unreachable_groups"] == [0, 1]
    fixed = apply_edits(p, [ResolvedEdit(op="connect", source=2, target=0)])
    np.testing.assert_allclose(fixed[2], [0.5, 0.0, 0.5])  # as likely as the row's average transition


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
