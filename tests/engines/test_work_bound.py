"""Every engine's search is bounded by work, not by the clock (issue 29): a seeded request gives
the same bytes on a slow or busy machine, and ``budget_s`` is only a cap whose cut the ``done``
event and the report state (``stopped``)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from typing import Any

import pytest

import engines.base
from engines.annotations.engine import AnnotationEngine
from engines.base import Engine, Run, Stopped
from engines.control.engine import ControlEngine
from engines.graph.search import GraphSearch
from engines.library import library_to_arrays
from engines.registry import parse_job_request
from engines.rhythm.engine import RhythmEngine
from motion.bvh import bvh_text
from schemas import EventType, Report
from schemas.annotations import AnnotationRequest
from schemas.graph import GraphRequest
from schemas.rhythm import RhythmDatabaseSpec
from tests.engines.emitters import Collect
from workers.execute import run_search

from .graph_synthetic import synthetic_graph
from .rhythm_synthetic import library as rhythm_library
from .test_annotations import SPEC as ANNOTATED_SPEC
from .test_annotations import _library as annotated_library
from .test_control import walk_engine
from .test_graph_search import request as graph_request

TIMINGS = {"elapsed_s", "prep_s", "solve_s", "retime_s", "post_s"}
"""Report metrics that are timings (the only part of a result allowed to differ between runs)."""


def slow_clock(factor: float) -> Callable[[], float]:
    """A clock running ``factor`` times faster than the real one: the machine looks ``factor``
    times slower to anything that measures time."""
    import time

    t0 = time.perf_counter()
    return lambda: t0 + (time.perf_counter() - t0) * factor


def fingerprint(out: Collect) -> list[tuple[float, str, list[tuple[str, int]], dict[str, float]]]:
    """Every emitted solution as bytes a client sees (BVH text, score, provenance, metrics minus timings)."""
    return [
        (
            s.score,
            bvh_text(s.motion),
            list(s.provenance),
            {k: v for k, v in s.metrics.items() if k not in TIMINGS},
        )
        for s in out.solutions
    ]


# -- the shared helper ----------------------------------------------------------------------------
def test_run_records_why_it_stopped(monkeypatch: pytest.MonkeyPatch) -> None:
    assert Run(10.0, lambda: False).outcome() is Stopped.work
    flag = [False]
    run = Run(10.0, lambda: flag[0], poll_s=0.0)
    assert not run.over()
    flag[0] = True
    assert run.over() and run.outcome() is Stopped.cancelled
    monkeypatch.setattr(engines.base, "CLOCK", slow_clock(1e6))
    late = Run(1.0, lambda: False)
    assert late.over() and late.outcome() is Stopped.budget
    assert "may differ" in Stopped.budget.reason


# -- graph ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def graph() -> Any:
    return synthetic_graph()


def graph_run(graph: Any, req: GraphRequest) -> tuple[Collect, Stopped]:
    library, tree, tracks = graph
    out = Collect()
    stopped = GraphSearch(library, tree, tracks, req.seed).run(req, req.budget_s, out, lambda: False)
    return out, stopped


def test_graph_same_bytes_on_a_slow_machine(graph: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    req = graph_request(rounds=3, alternatives=2, budget_s=3600)
    first, stopped = graph_run(graph, req)
    assert stopped is Stopped.work and len(first.solutions) >= 2
    monkeypatch.setattr(engines.base, "CLOCK", slow_clock(50.0))
    again, stopped = graph_run(graph, req)
    assert stopped is Stopped.work
    assert fingerprint(again) == fingerprint(first)


def test_graph_same_bytes_beside_a_cpu_hog(graph: Any) -> None:
    req = graph_request(rounds=2, alternatives=1, budget_s=3600)
    first, _ = graph_run(graph, req)
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        busy, stopped = graph_run(graph, req)
    finally:
        proc.kill()
        proc.wait()
    assert stopped is Stopped.work
    assert fingerprint(busy) == fingerprint(first)


def test_graph_tiny_budget_still_answers_and_says_budget(graph: Any) -> None:
    out, stopped = graph_run(graph, graph_request(budget_s=1e-6, alternatives=1))
    assert stopped is Stopped.budget
    assert out.solutions  # the first seeds are drawn whatever the clock


# -- annotations ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def annotated() -> AnnotationEngine:
    lib = annotated_library()
    arrays = AnnotationEngine.build(ANNOTATED_SPEC, lib, Collect(), lambda: False)
    arrays.update(library_to_arrays(lib))
    return AnnotationEngine(lib, arrays)


def annotation_request(**kw: Any) -> AnnotationRequest:
    body: dict[str, Any] = {
        "engine": "annotations",
        "frames": 120,
        "seed": 5,
        "passes": 6,
        "budget_s": 3600,
        "timeline": [
            {"label": "slow", "start": 0, "end": 60, "value": 1},
            {"label": "fast", "start": 60, "end": 120, "value": 1},
        ],
    }
    return AnnotationRequest.model_validate(body | kw)


def search(engine: Engine, req: Any) -> tuple[Collect, Stopped]:
    out = Collect()
    return out, engine.search(req, Run(req.budget_s, emit=out))


def test_annotations_do_their_passes_at_any_clock_speed(
    annotated: AnnotationEngine, monkeypatch: pytest.MonkeyPatch
) -> None:
    req = annotation_request()
    first, stopped = search(annotated, req)
    assert stopped is Stopped.work and first.solutions
    monkeypatch.setattr(engines.base, "CLOCK", slow_clock(50.0))
    again, stopped = search(annotated, req)
    assert stopped is Stopped.work
    assert fingerprint(again) == fingerprint(first)
    assert first.solutions[-1].metrics["passes"] <= req.passes


def test_annotation_passes_are_validated() -> None:
    with pytest.raises(ValueError, match="passes"):
        annotation_request(passes=0)
    with pytest.raises(ValueError, match="passes"):
        annotation_request(passes=10**6)


# -- control ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def control() -> ControlEngine:
    return walk_engine()


def control_request(**kw: Any) -> Any:
    points = [[0.03 * i, 0.002 * i * i / 90] for i in range(90)]
    body = {"engine": "control", "control": {"trajectory": {"fps": 30, "points": points}}, "seed": 2}
    return parse_job_request(body | kw)


def test_control_same_bytes_beside_a_cpu_hog(control: ControlEngine) -> None:
    req = control_request(budget_s=3600)
    first, _ = search(control, req)
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        busy, stopped = search(control, req)
    finally:
        proc.kill()
        proc.wait()
    assert stopped is Stopped.work and busy.solutions
    assert fingerprint(busy) == fingerprint(first)


def test_control_same_bytes_at_any_clock_speed(
    control: ControlEngine, monkeypatch: pytest.MonkeyPatch
) -> None:
    req = control_request(budget_s=3600)
    first, _ = search(control, req)
    monkeypatch.setattr(engines.base, "CLOCK", slow_clock(50.0))
    again, stopped = search(control, req)
    assert stopped is Stopped.work
    assert fingerprint(again) == fingerprint(first)


# -- rhythm -----------------------------------------------------------------------------------------
def test_rhythm_is_one_pass_whatever_the_budget() -> None:
    lib, beats = rhythm_library()
    spec = RhythmDatabaseSpec.model_validate(
        {
            "kind": "rhythm",
            "clips": [{"bvh": f"{n}.bvh"} for n in lib.names],
            "beats_per_movement": 2,
            "clip_beats": beats,
        }
    )
    engine = RhythmEngine(lib, RhythmEngine.build(spec, lib, Collect(), lambda: False))
    req = parse_job_request({"engine": "rhythm", "music": {"bpm": 100, "duration_s": 6}, "seed": 4})
    first, stopped = search(engine, req)
    assert stopped is Stopped.work
    tiny = req.model_copy(update={"budget_s": 1e-6})
    again, stopped = search(engine, tiny)
    assert stopped is Stopped.work  # the single pass is the work: the cap never cuts it
    assert fingerprint(again) == fingerprint(first)


# -- the runtime: done event and report --------------------------------------------------------------
def run_job(engine: Engine, req: Any) -> tuple[list[tuple[EventType, dict[str, Any]]], dict[str, Report]]:
    events: list[tuple[EventType, dict[str, Any]]] = []
    reports: dict[str, Report] = {}

    def save(rid: str, motion: Any, report: Report) -> None:
        reports[rid] = report

    run_search(engine, req, "j1", lambda t, d: events.append((t, d)), lambda: False, save)
    return events, reports


@pytest.mark.parametrize("which", ["control", "annotations"])
def test_tiny_budget_says_budget_in_done_and_report(
    which: str, control: ControlEngine, annotated: AnnotationEngine
) -> None:
    engine: Engine = control if which == "control" else annotated
    req = control_request(budget_s=1e-6) if which == "control" else annotation_request(budget_s=1e-6)
    events, reports = run_job(engine, req)
    kind, done = events[-1]
    assert kind == EventType.done
    assert done["stopped"] == "budget" and "may differ" in done["stopped_reason"]
    best = reports[done["result"]]
    assert best.stopped == "budget" and best.stopped_reason == done["stopped_reason"]


def test_unhurried_run_says_work(control: ControlEngine) -> None:
    events, reports = run_job(control, control_request(budget_s=3600))
    kind, done = events[-1]
    assert kind == EventType.done and done["stopped"] == "work"
    assert reports[done["result"]].stopped == "work"
    # intermediate results carry no stop reason (their search was still running)
    assert all(r.stopped is None for rid, r in reports.items() if rid != done["result"])
