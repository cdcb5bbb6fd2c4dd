"""A request whose goal is missed on a graph that left clips out says so in its report."""

from __future__ import annotations

from engines.base import Run
from engines.graph.build import build_graph
from engines.graph.engine import GraphEngine, left_out_note
from engines.registry import parse_job_request
from tests.engines.emitters import Collect
from tests.engines.test_graph_build import arms_up, library, spec
from tests.motion.synthetic import walking_biped


def test_missed_goal_names_the_clips_left_out() -> None:
    lib = library(walking_biped(150, seed=0), walking_biped(150, seed=1), arms_up(walking_biped(150, seed=2)))
    arrays = build_graph(spec(), lib, Collect(), lambda: False)
    note = left_out_note(arrays)
    assert note is not None and "left out 1 clips (150 frames)" in note and "300 of 450 frames" in note
    engine = GraphEngine(lib, arrays)
    request = parse_job_request(
        {
            "engine": "graph",
            "frames": 60,
            "seed": 1,
            "budget_s": 5,
            "rounds": 3,
            "constraints": [
                {"type": "body", "frame": 0, "position": [0.0, 0.0]},
                {"type": "body", "frame": 59, "position": [0.0, 60.0]},  # 60 m in 2 s: out of reach
            ],
        }
    )
    emit = Collect()
    engine.search(request, Run(5.0, emit=emit))
    best = emit.best
    assert best is not None and best.quality is not None and not best.quality.ok
    assert note in best.quality.reasons


def test_no_note_when_every_clip_is_kept() -> None:
    lib = library(walking_biped(150, seed=0), walking_biped(150, seed=1))
    assert left_out_note(build_graph(spec(), lib, Collect(), lambda: False)) is None
    assert left_out_note({}) is None
