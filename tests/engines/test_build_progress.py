"""A database build's progress: one fraction that only moves forward, every phase named
(engines/progress.py). Before, a graph build reported 50 % (the motion library) and then 0 % (its
own first step), and the other kinds' steps were unnamed."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from engines.base import BUILD_PHASES, CollectingEmitter
from engines.library import ClipInput
from engines.progress import PhasedProgress
from engines.registry import UnavailableError, kind_class
from schemas.bases import DatabaseSpecBase
from service.demos import DEMOS
from workers.local import load_spec_file


def _spec_and_clips(spec: dict[str, Any], tmp: Path) -> tuple[DatabaseSpecBase, list[ClipInput]]:
    path = tmp / "db.json"
    path.write_text(json.dumps(spec))
    parsed, clips, _ = load_spec_file(path)
    return parsed, clips


@pytest.mark.parametrize("demo", ["graph", "annotations", "rhythm", "walk"])
def test_a_builds_progress_moves_forward_phase_by_phase(demo: str, tmp_path: Path) -> None:
    spec = DEMOS[demo].spec
    try:
        cls = kind_class(spec["kind"])
    except UnavailableError as exc:
        pytest.skip(str(exc))
    emit = CollectingEmitter()
    cls.build_database(*_spec_and_clips(spec, tmp_path), emit, lambda: False)
    fractions = [f for f, _ in emit.progress_events]
    assert fractions == sorted(fractions), emit.progress_events
    assert fractions[0] >= 0.0 and fractions[-1] <= 1.0
    phases = [m.split(": ", 1)[0] for _, m in emit.progress_events]
    assert all(": " in m for _, m in emit.progress_events), emit.messages
    assert (
        phases[0] == "reading clips" and phases[1] == "motion library" and phases[-1] == "quality reference"
    )
    assert cls.name in phases  # the kind's own steps, under its name
    kind = [f for f, m in emit.progress_events if m.startswith(f"{cls.name}: ")]
    assert BUILD_PHASES["library"] <= min(kind) and max(kind) <= BUILD_PHASES["kind"]


def test_phases_hold_the_fraction_where_it_was() -> None:
    emit = CollectingEmitter()
    p = PhasedProgress(emit)
    p.report(0.5, "library", "1816 frames")
    graph = p.phase("graph", 0.1, 0.9)
    graph.progress(0.0, "graph: features")  # a phase that starts below where the last ended
    graph.progress(0.8, "transitions")
    graph.progress(0.7, "pruning")  # and one that goes back
    assert emit.progress_events == [
        (0.5, "library: 1816 frames"),
        (0.5, "graph: features"),
        (pytest.approx(0.74), "graph: transitions"),
        (pytest.approx(0.74), "graph: pruning"),
    ]
    assert PhasedProgress.of(p) is p
    with pytest.raises(ValueError, match="part of"):
        p.phase("x", 0.5, 0.2)
