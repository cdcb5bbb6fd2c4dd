"""Annotation engine (Arikan, Forsyth & O'Brien 2003) on synthetic walkers whose labels are known:
slow walkers (0.6-0.7 m/s) and fast ones (1.6-1.8 m/s), one of each labelled, the others
labelled by the SVMs."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from engines.annotations.corrections import apply_corrections, propagated_ranges
from engines.annotations.dp import solve_chain
from engines.annotations.engine import AnnotationEngine, AnnotationSearch
from engines.annotations.propagate import known_labels
from engines.annotations.search import (
    Candidate,
    Problem,
    blocks_to_sigma,
    refine_boundaries,
    solve_level,
    spliced,
)
from engines.base import EngineError, Run
from engines.library import MotionLibrary, library_to_arrays
from schemas.annotations import AnnotatedDatabaseSpec, AnnotationRequest, FrameConstraint, LabelCorrection
from tests.engines.emitters import Collect
from tests.engines.graph_synthetic import arc_biped

FRAMES = 90
KINDS = {"slow": (0.6, 0.65, 0.7), "fast": (1.6, 1.7, 1.8)}


def _library() -> MotionLibrary:
    names, motions, labels = [], [], []
    for kind, speeds in KINDS.items():
        for i, v in enumerate(speeds):
            names.append(f"{kind}{i}")
            motions.append(arc_biped(FRAMES, v, 0.0, seed=len(names)))
            lab = ({"label": kind, "start": 0, "end": FRAMES, "value": 1},) if i == 0 else ()
            labels.append(lab)
    return MotionLibrary(tuple(names), tuple(motions), tuple(labels))


SPEC = AnnotatedDatabaseSpec(
    clips=[{"bvh": f"{k}{i}.bvh"} for k, s in KINDS.items() for i in range(len(s))],
    block_sizes=[16, 8],
    coarse_clusters=8,
    blocks_per_cluster=20,
    gammas=[1.0],
)


@pytest.fixture(scope="module")
def engine() -> AnnotationEngine:
    lib = _library()
    rec = Collect()
    arrays = AnnotationEngine.build(SPEC, lib, rec, lambda: False)
    assert any("label 'slow'" in m for m in rec.messages)
    arrays.update(library_to_arrays(lib))
    return AnnotationEngine(lib, arrays)


def _truth(engine: AnnotationEngine, clip: str) -> str:
    return "slow" if clip.startswith("slow") else "fast"


def test_propagation_labels_unlabelled_clips(engine: AnnotationEngine) -> None:
    db = engine.db
    assert db.vocab == ["slow", "fast"]
    truth = np.array([0 if db.names[c].startswith("slow") else 1 for c in db.clip_of])
    for j in range(2):
        assert np.mean((db.labels[:, j] > 0) == (truth == j)) > 0.97


def test_known_labels_semantics() -> None:
    labels = [
        [{"label": "walk", "start": 0, "end": 4, "value": 1}],
        [{"label": "wave", "start": 1, "end": 3, "value": -1}],
    ]
    values, known = known_labels(labels, [5, 4], ["walk", "wave"])
    # a +1 range annotates fully: walk +1, wave -1 on frames 0-3 of clip 0; frame 4 unknown
    assert values[:4].tolist() == [[1, -1]] * 4 and not known[4].any()
    # a -1 range only speaks for its label
    assert known[6].tolist() == [False, True] and values[6, 1] == -1


def test_search_follows_timeline(engine: AnnotationEngine) -> None:
    req = AnnotationRequest(
        frames=120,
        seed=2,
        timeline=[{"label": "slow", "start": 0, "end": 60}, {"label": "fast", "start": 60, "end": 120}],
        footskate=False,
    )
    rec = Collect()
    engine.search(req, Run(0.3, emit=rec))
    assert rec.solutions, "no solution emitted"
    scores = [s.score for s in rec.solutions]
    assert scores == sorted(scores, reverse=True) and len(set(scores)) == len(scores)
    best = rec.solutions[-1]
    assert best.motion.num_frames == 120 and len(best.provenance) == 120
    steady = [i for i in range(120) if abs(i - 60) >= 15]
    ok = [_truth(engine, best.provenance[i][0]) == ("slow" if i < 60 else "fast") for i in steady]
    assert np.mean(ok) >= 0.95
    assert best.metrics["label_match_steady"] >= 0.95
    assert best.annotations["requested"]["slow"][0] == 1 and len(best.annotations["achieved"]["fast"]) == 120


def test_unknown_label_is_a_client_error(engine: AnnotationEngine) -> None:
    req = AnnotationRequest(frames=40, timeline=[{"label": "jump", "start": 0, "end": 40}])
    with pytest.raises(EngineError, match="jump"):
        engine.search(req, Run(0.1, emit=Collect()))


def test_dp_matches_brute_force() -> None:
    rng = np.random.default_rng(0)
    unary = rng.normal(size=(4, 3))
    pairs = rng.normal(size=(4, 3, 3))
    choice, cost = solve_chain(unary, lambda k: pairs[k])
    best = min(
        (sum(unary[k, c[k]] for k in range(4)) + sum(pairs[k, c[k - 1], c[k]] for k in range(1, 4)), c)
        for c in itertools.product(range(3), repeat=4)
    )
    assert cost == pytest.approx(best[0]) and tuple(choice) == best[1]


def test_level_dp_is_optimal_for_the_frame_objective(engine: AnnotationEngine) -> None:
    """The block DP's optimum equals the best exact frame objective over all block sequences."""
    db = engine.db
    req = AnnotationRequest(
        frames=40,
        timeline=[{"label": "slow", "start": 0, "end": 20}, {"label": "fast", "start": 20, "end": 40}],
    )
    pb = Problem.compile(req, db)
    rng = np.random.default_rng(1)
    valid = db.levels[-1].members
    active = rng.choice(valid, size=(5, 3))  # 5 slots of 8 frames, 3 candidates each
    starts, cost = solve_level(db, pb, active, 8)
    brute = min(
        Candidate.of(db, pb, blocks_to_sigma(np.array(c), 8, 40)).score
        for c in itertools.product(*[list(a) for a in active])
    )
    assert cost == pytest.approx(brute)
    assert Candidate.of(db, pb, blocks_to_sigma(starts, 8, 40)).score == pytest.approx(brute)


def test_refinement_never_worsens(engine: AnnotationEngine) -> None:
    db = engine.db
    req = AnnotationRequest(frames=48, timeline=[{"label": "fast", "start": 0, "end": 48}])
    pb = Problem.compile(req, db)
    rng = np.random.default_rng(3)
    for _ in range(5):
        sigma = blocks_to_sigma(rng.choice(db.levels[-1].members, size=6), 8, 48)
        refined = refine_boundaries(db, pb, sigma, 4)
        assert Candidate.of(db, pb, refined).score <= Candidate.of(db, pb, sigma).score + 1e-9


def test_frame_constraint_is_honoured(engine: AnnotationEngine) -> None:
    req = AnnotationRequest(
        frames=80,
        seed=1,
        timeline=[{"label": "fast", "start": 0, "end": 80}],
        frame_constraints=[{"frame": 37, "clip": "slow2", "clip_frame": 50}],
        footskate=False,
    )
    rec = Collect()
    engine.search(req, Run(0.2, emit=rec))
    best = rec.solutions[-1]
    assert best.provenance[37] == ("slow2.bvh", 50)
    assert best.constraint_errors["frame[0]"]["met"] is True
    # two constraints inside one 8-frame block, from different clips, and one at the last frame
    close = [
        {"frame": 10, "clip": "fast1", "clip_frame": 3},
        {"frame": 12, "clip": "slow0", "clip_frame": 80},
        {"frame": 79, "clip": "slow1", "clip_frame": 89},
    ]
    rec = Collect()
    engine.search(
        req.model_copy(update={"frame_constraints": [FrameConstraint(**c) for c in close]}),
        Run(0.2, emit=rec),
    )
    best = rec.solutions[-1]
    assert [best.provenance[t] for t in (10, 12, 79)] == [
        ("fast1.bvh", 3),
        ("slow0.bvh", 80),
        ("slow1.bvh", 89),
    ]


def test_splice_score_matches_exact_score(engine: AnnotationEngine) -> None:
    """The O(1) single-cut score (Sec. 3.4) equals the score of the spliced sequence."""
    db = engine.db
    req = AnnotationRequest(
        frames=48,
        timeline=[{"label": "slow", "start": 0, "end": 48}],
        end={"position": [1.0, 2.0], "heading_deg": 30},
    )
    pb = Problem.compile(req, db)
    rng = np.random.default_rng(5)
    x = Candidate.of(db, pb, blocks_to_sigma(rng.choice(db.levels[-1].members, size=6), 8, 48))
    y = Candidate.of(db, pb, blocks_to_sigma(rng.choice(db.levels[-1].members, size=6), 8, 48))
    score, k = spliced(db, pb, x, y, 8)
    z = Candidate.of(db, pb, np.concatenate((x.sigma[:k], y.sigma[k:])))
    assert score == pytest.approx(z.score)


def test_end_constraint_pulls_the_end(engine: AnnotationEngine) -> None:
    base: dict[str, Any] = {"frames": 96, "seed": 4, "timeline": [{"label": "fast", "start": 0, "end": 96}]}
    free = AnnotationSearch(engine.db, AnnotationRequest(**base)).one_pass()
    goal = free.end_xz + np.array([0.5, -0.5])
    req = AnnotationRequest(**base, end={"position": goal.tolist()})
    state = AnnotationSearch(engine.db, req)
    err0 = float(np.linalg.norm(Candidate.of(engine.db, state.pb, free.sigma).end_xz - goal))
    best = min((state.one_pass() for _ in range(6)), key=lambda c: c.score)
    assert float(np.linalg.norm(best.end_xz - goal)) < err0


def test_corrections_make_a_new_spec(engine: AnnotationEngine) -> None:
    fixes = [
        LabelCorrection(clip="slow1", start=0, end=90, action="accept"),
        LabelCorrection(clip="fast2.bvh", start=10, end=30, label="slow", value=-1),
    ]
    new = apply_corrections(SPEC, fixes, engine.db)
    got = {(lb.label, lb.value) for lb in new.clips[1].labels}
    assert ("slow", 1) in got and ("fast", -1) in got
    assert [(lb.label, lb.start, lb.end, lb.value) for lb in new.clips[5].labels] == [("slow", 10, 30, -1)]
    assert propagated_ranges(engine.db, "slow1")[0]["label"] == "slow"
    with pytest.raises(EngineError):
        apply_corrections(SPEC, [LabelCorrection(clip="nope", start=0, end=5, label="slow")], engine.db)


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"frames": 10, "timeline": [{"label": "a", "start": 0, "end": 20}]}, "after the motion"),
        ({"frames": 10, "timeline": [{"label": "a", "start": 5, "end": 5}]}, "must be after"),
        ({"frames": 10, "timeline": [{"label": "a", "start": 0, "end": 5, "value": 2}]}, "value"),
        ({"frames": 10, "alpha": 1.5}, "alpha"),
        (
            {"frames": 10, "frame_constraints": [{"frame": 3, "clip": "a", "clip_frame": 0}] * 2},
            "two frame constraints",
        ),
        ({"frames": 10, "bogus": 1}, "bogus"),
    ],
)
def test_request_validation(data: dict[str, Any], match: str) -> None:
    with pytest.raises(ValidationError, match=match):
        AnnotationRequest(**data)


def test_spec_validation() -> None:
    with pytest.raises(ValidationError, match="block_sizes"):
        AnnotatedDatabaseSpec(clips=[{"bvh": "a.bvh"}], block_sizes=[32, 12])
    with pytest.raises(ValidationError, match="label"):
        LabelCorrection(clip="a", start=0, end=4)


def test_strided_decision_interpolates_within_clips() -> None:
    from engines.annotations.propagate import strided_decision

    class Linear:
        def decision_function(self, x: np.ndarray) -> np.ndarray:
            return np.asarray(x[:, 0])

    counts = [7, 5]
    local = np.concatenate([np.arange(n) for n in counts]).astype(np.float64)
    emb = np.stack((2.0 * local - 3.0, np.zeros_like(local)), axis=1)
    clip_of = np.repeat(np.arange(2), counts)
    frames = np.arange(12)
    got = strided_decision(Linear(), emb, clip_of, counts, frames, 3)  # type: ignore[arg-type]
    np.testing.assert_allclose(got, emb[:, 0], atol=1e-6)


def test_confidence_weights_propagated_labels(engine: AnnotationEngine) -> None:
    db = engine.db
    timeline = [{"label": "slow", "start": 0, "end": 10}]
    soft = Problem.compile(AnnotationRequest(frames=10, timeline=timeline), db)
    hard = Problem.compile(AnnotationRequest(frames=10, timeline=timeline, confidence=False), db)
    known = np.asarray(engine.arrays["ann.known"])[:, 0]
    np.testing.assert_array_equal(soft.lab[known, 0], hard.lab[known, 0])  # user labels count +-1
    assert np.all(np.abs(soft.lab[:, 0]) <= 1.0)
    assert np.all(np.sign(soft.lab[~known, 0]) * hard.lab[~known, 0] >= 0)  # same sign as the label
    assert np.any(np.abs(soft.lab[~known, 0]) < 1.0)


def test_loop_option_closes_the_clip_and_is_reported(engine: AnnotationEngine) -> None:
    req = AnnotationRequest(
        frames=120, seed=2, timeline=[{"label": "slow", "start": 0, "end": 120}], footskate=False, loop=True
    )
    rec = Collect()
    engine.search(req, Run(0.3, emit=rec))
    best = rec.solutions[-1]
    loop = best.constraint_errors["loop"]
    assert loop["satisfied"] and loop["pose_cm"] < 1.0 and loop["last_frame"] == 119, loop


def test_the_database_dataclass_writes_back_the_stored_arrays(engine: AnnotationEngine) -> None:
    """:class:`engines.annotations.database.AnnotatedDatabase`: ``to_arrays`` of what
    ``from_arrays`` read is the stored ``ann.*`` arrays (order, dtypes, bytes)."""
    from engines.annotations.database import AnnotatedDatabase
    from tests.engines.database_arrays import assert_same_arrays

    stored = AnnotatedDatabase.from_arrays(engine.arrays)
    assert list(stored.clusters) == [int(s) for s in SPEC.block_sizes]
    assert_same_arrays(engine.arrays, stored.to_arrays(), "ann.")
