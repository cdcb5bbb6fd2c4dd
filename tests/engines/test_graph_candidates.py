"""Candidate transitions from the nearest-neighbour index (engines.graph.candidates): the minima it
keeps are the all-pairs scan's, all of them when every pair is a seed; reproducible."""

from __future__ import annotations

import json

import numpy as np
import pytest

from engines.base import EngineError
from engines.graph import candidates
from engines.graph.build import (
    bridge_edges,
    build_graph,
    candidate_edges,
    local_minima,
    merge_edges,
    screen_rows,
    use_index,
)
from engines.graph.candidates import frame_index, indexed_minima
from engines.graph.features import transition_features
from engines.graph.hierarchy import LeafEdges
from engines.graph.model import EdgeTree
from engines.library import MotionLibrary
from tests.engines.emitters import Collect
from tests.engines.test_graph_build import brute_force_minima, dense_costs, library, spec
from tests.motion.synthetic import walking_biped


def smooth_rows(seed: int, lengths: list[int], dims: int = 5) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    parts = [np.cumsum(rng.normal(size=(k, dims)), axis=0) * 0.3 for k in lengths]
    rows = np.concatenate(parts).astype(np.float32)
    return rows, np.concatenate(([0], np.cumsum(lengths))).astype(np.int64)


@pytest.mark.parametrize("seed", [3, 4])
def test_every_pair_a_seed_finds_exactly_the_all_pairs_minima(seed: int) -> None:
    rows, offsets = smooth_rows(seed, [23, 40, 17])
    tau = float(np.quantile(dense_costs(rows), 0.3))
    x, y, v, stats = indexed_minima(rows, offsets, tau, 4, neighbours=rows.shape[0], stride=1, workers=2)
    got = set(zip(x.tolist(), y.tolist(), strict=True))
    assert got == brute_force_minima(rows, offsets, tau, 4)
    assert stats.minima == x.size == len(got)
    assert np.all(np.diff(x * rows.shape[0] + y) > 0)  # sorted by (x, y), no repeats
    np.testing.assert_allclose(v, dense_costs(rows)[x, y], rtol=1e-4, atol=1e-4)


def test_few_seeds_keep_a_subset_of_the_minima_reproducibly() -> None:
    rows, offsets = smooth_rows(5, [300, 250, 400, 120], dims=8)
    tau = float(np.quantile(dense_costs(rows), 0.05))
    ax, ay, _, _ = local_minima(rows, offsets, tau, 10)
    exact = set(zip(ax.tolist(), ay.tolist(), strict=True))
    runs = [indexed_minima(rows, offsets, tau, 10, neighbours=4, stride=2, workers=w) for w in (1, 2, 1)]
    x, y, v, stats = runs[0]
    got = set(zip(x.tolist(), y.tolist(), strict=True))
    assert got and got <= exact
    assert len(got) < len(exact)  # 4 seeds per frame do not reach every basin
    assert stats.seeds <= 4 * (rows.shape[0] // 2 + 1)
    for other in runs[1:]:
        for a, b in zip(runs[0][:3], other[:3], strict=True):
            np.testing.assert_array_equal(a, b)


def test_indexed_minima_errors_and_tiny_inputs() -> None:
    rows, offsets = smooth_rows(1, [30])
    with pytest.raises(EngineError, match="neighbours"):
        indexed_minima(rows, offsets, 1.0, 4, neighbours=0)
    x, _, _, stats = indexed_minima(rows[:1], np.array([0, 1]), 1.0, 4)
    assert x.size == 0 and stats.minima == 0


def test_use_index_by_method_and_size() -> None:
    assert use_index("indexed", 10) and not use_index("all_pairs", 10**7)
    assert not use_index("auto", 1000) and use_index("auto", 10**6)
    with pytest.raises(EngineError, match="candidates"):
        use_index("fast", 10)


@pytest.fixture(scope="module")
def walks() -> MotionLibrary:
    return library(walking_biped(150, seed=0), walking_biped(150, seed=1, heading_deg=90.0))


def test_indexed_build_keeps_edges_of_the_all_pairs_build(walks: MotionLibrary) -> None:
    exact = build_graph(spec(candidates="all_pairs"), walks, Collect(), lambda: False)
    emit = Collect()
    fast = build_graph(spec(candidates="indexed"), walks, emit, lambda: False)
    report = json.loads(str(fast["graph.report"]))
    assert report["candidates"] == "indexed" and report["seeds"] > 0
    assert json.loads(str(exact["graph.report"]))["candidates"] == "all_pairs"

    def leaves(arrays: dict[str, np.ndarray]) -> set[tuple[int, ...]]:
        t = EdgeTree.from_arrays(arrays)
        m = t.is_leaf
        cols = (t.from_clip, t.from_frame, t.to_clip, t.to_frame)
        return set(zip(*(a[m].tolist() for a in cols), strict=True))

    got, want = leaves(fast), leaves(exact)
    assert got and got <= want
    # cross-clip edges both ways survive (the two walks stay one component)
    assert {(a, c) for a, _, c, _ in got} >= {(0, 1), (1, 0)}
    fractions = [f for f, _ in emit.progress_events]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert any("transition candidates" in m for _, m in emit.progress_events)
    tf = transition_features(walks)
    assert report["frames"] == tf.rows.shape[0]


def test_bridge_edges_are_all_pairs_edges_of_the_clips_asked(walks: MotionLibrary) -> None:
    tf = transition_features(walks)
    screen = screen_rows(tf)
    exact, _ = candidate_edges(tf, 1.0, 10, method="all_pairs", screen=screen)
    extra = bridge_edges(tf, screen, np.array([1]), 1.0, 10)

    def keys(e: LeafEdges) -> set[tuple[int, int, int, int]]:
        cols = (e.from_clip, e.from_frame, e.to_clip, e.to_frame)
        return set(zip(*(c.tolist() for c in cols), strict=True))

    got = keys(extra)
    assert got and got <= keys(exact)
    assert all(1 in (a, c) for a, _, c, _ in got)  # every edge touches the clip asked
    assert {(a, c) for a, _, c, _ in got} >= {(0, 1), (1, 0)}
    assert bridge_edges(tf, screen, np.zeros(0, dtype=np.int64), 1.0, 10).size == 0


def test_bridge_asks_the_builds_own_index(walks: MotionLibrary, monkeypatch: pytest.MonkeyPatch) -> None:
    """The second search reuses the first one's index (no second training over every frame) and
    finds the same edges as with an index of its own."""
    tf = transition_features(walks)
    screen = screen_rows(tf)
    own = bridge_edges(tf, screen, np.array([1]), 1.0, 10)
    index = frame_index(screen, workers=2)

    def no_second_index(*args: object, **kwargs: object) -> None:
        raise AssertionError("the bridge built a second index")

    monkeypatch.setattr(candidates, "frame_index", no_second_index)
    shared = bridge_edges(tf, screen, np.array([1]), 1.0, 10, index=index)
    for name in ("from_clip", "from_frame", "to_clip", "to_frame", "cost"):
        np.testing.assert_array_equal(getattr(shared, name), getattr(own, name))


def test_an_index_of_other_rows_is_refused() -> None:
    rows, offsets = smooth_rows(2, [40, 30])
    index = frame_index(rows[:50], stride=2)
    with pytest.raises(EngineError, match="holds 25 rows"):
        indexed_minima(rows, offsets, 1.0, 4, index=index)


def test_merge_edges_is_a_sorted_union() -> None:
    a = LeafEdges(
        np.array([0, 1]), np.array([5, 7]), np.array([1, 0]), np.array([9, 2]), np.array([0.1, 0.2])
    )
    b = LeafEdges(
        np.array([0, 0]), np.array([5, 3]), np.array([1, 1]), np.array([9, 4]), np.array([0.1, 0.3])
    )
    m = merge_edges(a, b)
    cols = (m.from_clip, m.from_frame, m.to_clip, m.to_frame)
    assert list(zip(*(c.tolist() for c in cols), strict=True)) == [(0, 3, 1, 4), (0, 5, 1, 9), (1, 7, 0, 2)]
    assert m.cost.tolist() == [0.3, 0.1, 0.2]
