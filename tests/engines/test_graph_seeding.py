"""Graph search seeding: biased walkers, chain seeds of root edges and their vectorised polish."""

from __future__ import annotations

import numpy as np

from engines.base import Run
from engines.graph.paths import PathBatch, batch_pieces, batch_valid
from engines.graph.score import score_batch
from engines.graph.search import _Clock

from .test_graph_search import Collect, Graph, graph, prime, request, searcher  # noqa: F401


def test_chains_are_valid_and_can_play_the_length(graph: Graph) -> None:  # noqa: F811
    gs = searcher(graph)
    req = request()
    prime(gs, req)
    T = gs._problem.length
    chains = gs._chains(T, np.random.default_rng(0))
    sizes = [e.shape[1] for e, _, _ in chains]
    assert sizes == sorted(set(sizes)) and sizes[-1] <= gs.chain_edges  # 150-frame clips: 2 or 3
    assert sum(e.shape[0] for e, _, _ in chains) > 100
    t = gs.tree
    roots = set(gs.index_.roots.tolist())
    for edges, lo, hi in chains:
        assert set(np.unique(edges).tolist()) <= roots
        assert np.all((lo >= 1) & (lo <= hi))
        first = edges[:, 0]
        for n0 in (lo, hi):
            batch = PathBatch(t.from_clip[first], t.from_frame[first] - n0 + 1, edges)
            assert batch_valid(gs.index_, batch).all()
            pieces = batch_pieces(gs.index_, batch, T)
            assert np.all(pieces.total >= T)  # plays the whole output ...
            assert np.all(pieces.start[:, -1] < T)  # ... with every cut inside it
            assert np.all(pieces.count[:, :-1] >= 1)


def test_polish_only_improves_and_keeps_full_length_paths(graph: Graph) -> None:  # noqa: F811
    gs = searcher(graph)
    prime(gs, request())
    T = gs._problem.length
    batch = gs._random_seeds(np.random.default_rng(3), 64)
    s = score_batch(gs.index_, gs._problem, batch)
    full = np.isfinite(s.total) & (s.pieces.total >= T)
    batch = batch.take(np.flatnonzero(full))
    before = s.total[full]
    clock = _Clock(Run(60.0, lambda: False))
    out, after = gs._polish(gs._problem, batch, before, clock)
    assert np.all(after <= before + 1e-12)
    assert np.any(after < before - 1e-6)
    again = score_batch(gs.index_, gs._problem, out)
    np.testing.assert_allclose(again.total, after, rtol=1e-12)
    assert np.all(again.pieces.total >= T)


def test_biased_walkers_cut_less(graph: Graph) -> None:  # noqa: F811
    gs = searcher(graph)
    prime(gs, request())
    plain = gs._random_seeds(np.random.default_rng(1), 400, 0.0)
    biased = gs._random_seeds(np.random.default_rng(1), 400, 1.0)
    assert batch_valid(gs.index_, biased).all()
    assert biased.n_edges.mean() < plain.n_edges.mean()
    T = gs._problem.length
    assert np.mean(batch_pieces(gs.index_, biased, T).total >= T) > 0.9


def test_chain_seeds_beat_random_seeds_alone(graph: Graph) -> None:  # noqa: F811
    req = request(alternatives=1)
    scores = {}
    for chains in (0, 3):
        out = Collect()
        searcher(graph, 3, chain_edges=chains).run(req, 60.0, out, lambda: False, max_rounds=0)
        scores[chains] = min(s.score for s in out.solutions)
        assert all(s.motion.num_frames == 240 for s in out.solutions)
    assert scores[3] < scores[0]
    # reproducible: same seed, same solutions
    out = Collect()
    searcher(graph, 3, chain_edges=3).run(req, 60.0, out, lambda: False, max_rounds=2)
    out2 = Collect()
    searcher(graph, 3, chain_edges=3).run(req, 60.0, out2, lambda: False, max_rounds=2)
    assert [s.score for s in out.solutions] == [s.score for s in out2.solutions]
    assert [s.provenance for s in out.solutions] == [s.provenance for s in out2.solutions]
