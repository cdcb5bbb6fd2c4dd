"""Every engine's results carry a quality report measured on the motion returned: a feasible
request is reported as the motion shows it, an infeasible one comes back `ok: false` with the
reason, and the motion stays within the examples' physical limits (no drag to meet a goal)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from engines.annotations.engine import AnnotationEngine
from engines.base import Run, Solution
from engines.graph.search import GraphSearch
from engines.library import library_to_arrays
from engines.registry import parse_job_request
from engines.rhythm.engine import RhythmEngine
from motion.goals import body_track
from motion.plausibility import reference_from_positions
from schemas.annotations import AnnotationRequest
from schemas.graph import GraphRequest
from schemas.rhythm import RhythmDatabaseSpec
from tests.engines.emitters import Collect
from tests.engines.graph_synthetic import synthetic_graph
from tests.engines.rhythm_synthetic import library as rhythm_library
from tests.engines.test_annotations import SPEC as ANN_SPEC
from tests.engines.test_annotations import _library as annotation_library
from tests.engines.test_control import walk_engine


def best(out: Collect) -> Solution:
    sol = out.best
    assert sol is not None and sol.quality is not None
    return sol


def graph_request(goal: tuple[float, float, float]) -> GraphRequest:
    return GraphRequest.model_validate(
        {
            "engine": "graph",
            "frames": 240,
            "seed": 3,
            "constraints": [
                {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
                {"type": "body", "frame": 239, "position": list(goal[:2]), "heading_deg": goal[2]},
            ],
        }
    )


@pytest.fixture(scope="module")
def graph_search() -> Any:
    library, tree, tracks = synthetic_graph()
    ref = reference_from_positions([(m.global_positions(), m.skeleton, m.fps) for m in library.motions])
    return lambda seed: GraphSearch(library, tree, tracks, seed, reference=ref)


def test_graph_unreachable_goal_is_reported_unmet_without_a_drag(graph_search: Any) -> None:
    out = Collect()
    graph_search(3).run(graph_request((0.0, 100.0, 0.0)), 60.0, out, lambda: False)
    sol = best(out)
    q = sol.quality
    assert q is not None and not q.ok
    body = q.constraint_errors["body[1]"]
    assert not body["satisfied"] and body["position_cm"] > 5000
    assert any(r.startswith("body[1]") and "reachable" in r for r in q.reasons)
    # the body never moves faster than the fastest example to pretend otherwise
    assert q.plausibility["root_speed"]["ok"] and q.plausibility["root_speed"]["ratio"] <= 1.0 + 1e-3
    # the report is the motion's: the end is where the report says
    xz, _ = body_track(sol.motion.global_positions(), sol.motion.skeleton)
    assert np.linalg.norm(xz[239] - [0.0, 100.0]) * 100 == pytest.approx(body["position_cm"], abs=1e-3)


def test_graph_reachable_goal_is_met_and_ok(graph_search: Any) -> None:
    out = Collect()
    graph_search(3).run(graph_request((2.0, 4.0, 60.0)), 60.0, out, lambda: False)  # rounds bound it
    q = best(out).quality
    assert q is not None
    assert q.constraint_errors["body[1]"]["satisfied"], q.reasons
    assert q.constraint_errors["length"]["satisfied"]


@pytest.fixture(scope="module")
def annotations() -> AnnotationEngine:
    lib = annotation_library()
    arrays = AnnotationEngine.build(ANN_SPEC, lib, Collect(), lambda: False)
    arrays.update(library_to_arrays(lib))
    return AnnotationEngine(lib, arrays)


def test_annotations_unreachable_end_and_label_goals(annotations: AnnotationEngine) -> None:
    timeline = [
        {"label": "fast", "start": 0, "end": 96},
        {"label": "slow", "start": 0, "end": 96, "value": -1},
    ]
    out = Collect()
    annotations.search(
        AnnotationRequest(frames=96, seed=4, timeline=timeline, end={"position": [0.0, 60.0]}),
        Run(60.0, emit=out),  # 60 s: a safety cap, the passes bound the work
    )
    q = best(out).quality
    assert q is not None and not q.ok
    assert not q.constraint_errors["end"]["satisfied"]
    assert any(r.startswith("end (frame 95)") for r in q.reasons)
    labels = [v for k, v in q.constraint_errors.items() if k.startswith("label[")]
    assert {(e["label"], e["value"]) for e in labels} == {("fast", 1), ("slow", -1)}
    assert all(e["satisfied"] for e in labels)
    assert q.constraint_errors["start"]["satisfied"]


def test_control_walk_that_cannot_keep_up_with_its_path_is_not_ok() -> None:
    """The examples walk at 1.0-1.4 m/s; a path at 3 m/s (within what a path may ask) leaves the
    walker behind, and the report says how far."""
    engine = walk_engine()
    t = np.arange(120) / 30.0
    path = np.stack((np.zeros_like(t), 3.0 * t), axis=-1)
    req = parse_job_request(
        {"engine": "control", "control": {"trajectory": {"fps": 30, "points": path.tolist()}}, "budget_s": 3}
    )
    out = Collect()
    engine.search(req, Run(60.0, emit=out))
    q = best(out).quality
    assert q is not None and not q.ok
    assert not q.constraint_errors["path"]["satisfied"] and q.constraint_errors["path"]["rms_cm"] > 10
    assert any(r.startswith("path:") for r in q.reasons)
    slow = parse_job_request(
        {"engine": "control", "control": {"trajectory": {"fps": 30, "points": (path / 2.5).tolist()}}}
    )
    out = Collect()
    engine.search(slow, Run(60.0, emit=out))
    path_error = best(out).constraint_errors["path"]
    assert path_error["satisfied"] and path_error["rms_cm"] < 10


@pytest.fixture(scope="module")
def rhythm() -> RhythmEngine:
    lib, beats = rhythm_library()
    spec = RhythmDatabaseSpec.model_validate(
        {
            "kind": "rhythm",
            "clips": [{"bvh": f"{n}.bvh"} for n in lib.names],
            "beats_per_movement": 2,
            "clip_beats": beats,
        }
    )
    arrays = RhythmEngine.build(spec, lib, Collect(), lambda: False)
    arrays.update(library_to_arrays(lib))
    return RhythmEngine(lib, arrays)


def test_rhythm_music_too_fast_to_dance_is_not_ok(rhythm: RhythmEngine) -> None:
    """At three times the examples' tempo the movements play three times as fast: the engine
    prefers those whose travel the tempo allows, but the limbs still move beyond anything the
    examples do (the accent never makes it worse than the unaccented warp)."""
    period = rhythm.tables.period_s
    req = parse_job_request(
        {"engine": "rhythm", "music": {"bpm": 3 * 60 / period, "duration_s": 6}, "seed": 1}
    )
    out = Collect()
    rhythm.search(req, Run(5.0, emit=out))
    q = best(out).quality
    assert q is not None and not q.ok
    assert "music" in q.constraint_errors and q.constraint_errors["length"]["satisfied"]
    assert any(w in r for r in q.reasons for w in ("speed", "turn rate", "slide", "joint step"))
    assert all(m["accent"] <= 0.6 for m in best(out).annotations["movements"])


def test_rhythm_at_the_examples_tempo_is_ok_and_reports_beats(rhythm: RhythmEngine) -> None:
    period = rhythm.tables.period_s
    req = parse_job_request({"engine": "rhythm", "music": {"bpm": 60 / period, "duration_s": 8}, "seed": 1})
    out = Collect()
    rhythm.search(req, Run(5.0, emit=out))
    q = best(out).quality
    assert q is not None
    plausible = {k: v["ok"] for k, v in q.plausibility.items()}
    assert all(plausible.values()), q.reasons
    assert q.constraint_errors["music"]["beat_align_bailando"] > 0.5
