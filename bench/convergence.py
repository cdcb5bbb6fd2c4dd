"""Benchmark: how each engine's score converges with its unit of work (what the defaults are picked from).

Every search is bounded by work (the graph's ``rounds``, the annotation engine's ``passes``, the
control engine's stages; the rhythm engine is one pass), so its default must reach a good answer in
about a second on a 2-core machine. For each example below this runs one search with a large work
bound and a large time cap, and records every emitted solution's work unit, score and time:

``{"<example>": {"engine", "work": "<unit>", "default": <default bound>, "curve": [[unit, score,
wall s, CPU s], ...], "final": {"unit", "score", "seconds", "cpu_s"}, "search_s", "search_cpu_s",
"within_1pct": [unit, wall s, CPU s], "within_5pct": [...], "at_default": [score, wall s, CPU s]},
"load": <1-min load average>}`` (seconds since the search started; the last solution of a unit is
emitted when the unit ends).

Examples: the README's graph and annotation examples (bundled clips), the graph engine on
Bandai-Namco locomotion (``../shared/data``, skipped when absent). The control engine's work is its
fixed ladder of stages and the rhythm engine's a single pass: neither has a curve to pick a default
from. Run it with ``nice``; the seconds depend on the machine's load, the units and scores do not.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engines.base import CollectingEmitter, Engine, Run, foot_floor_arrays  # noqa: E402
from engines.library import ClipInput, build_library, library_to_arrays  # noqa: E402
from engines.registry import kind_class, parse_database_spec, parse_job_request  # noqa: E402
from motion.allocator import tune_process  # noqa: E402
from motion.samples import resolve_path  # noqa: E402

BANDAI = ROOT.parent / "shared" / "data" / "bandai-namco" / "dataset-2"

GRAPH_SPEC = {
    "kind": "graph",
    "fps": 30,
    "tau": 1.0,
    "clips": [
        {"bvh": "sample:walk"},
        {"bvh": "sample:walk-05-01"},
        {"bvh": "sample:walk-10-04"},
        {"bvh": "sample:walk-12-02"},
        {"bvh": "sample:salsa-leader-02"},
    ],
}
GRAPH_REQUEST = {
    "engine": "graph",
    "frames": 240,
    "seed": 1,
    "alternatives": 3,
    "constraints": [
        {"type": "body", "frame": 0, "position": [0, 0], "heading_deg": 0},
        {"type": "body", "frame": 239, "position": [1.5, 8.0], "heading_deg": 20},
        {"type": "joint", "frame": 120, "joint": "head", "position": [0.5, 1.45, 4.0]},
        {"type": "obstacle", "disc": {"center": [0.3, 2.5], "radius": 0.3}},
    ],
}
ANNOTATED_SPEC = {
    "kind": "annotated",
    "clips": [
        {"bvh": "sample:walk", "labels": [{"label": "walk", "start": 1, "end": 80}]},
        {"bvh": "sample:walk-05-01", "labels": [{"label": "walk", "start": 1, "end": 150}]},
        {"bvh": "sample:run-09-01", "labels": [{"label": "run", "start": 1, "end": 38}]},
        {"bvh": "sample:run-09-02", "labels": [{"label": "run", "start": 1, "end": 33}]},
        {"bvh": "sample:jump-13-11", "labels": [{"label": "jump", "start": 1, "end": 104}]},
        {"bvh": "sample:walk-10-04"},
        {"bvh": "sample:run-09-03"},
        {"bvh": "sample:jump-13-32"},
    ],
}
ANNOTATION_REQUEST = {
    "engine": "annotations",
    "frames": 240,
    "seed": 3,
    "timeline": [
        {"label": "walk", "start": 0, "end": 150, "value": 1},
        {"label": "run", "start": 150, "end": 240, "value": 1},
        {"label": "jump", "start": 0, "end": 240, "value": -1},
    ],
}
WORK = {"graph": ("rounds", "search_rounds"), "annotations": ("passes", "passes")}


def load_engine(spec_data: dict[str, Any]) -> Engine:
    """A loaded engine of a spec whose clips are ``sample:NAME`` or paths."""
    spec = parse_database_spec(spec_data)
    clips = []
    for source in spec.clips:
        assert source.bvh is not None
        path = resolve_path(source.bvh, ROOT)
        labels = [lb.model_dump() for lb in source.labels]
        clips.append(ClipInput(source.display_name(), path.read_bytes(), source.units, labels))
    library = build_library(clips, spec.fps)
    cls = kind_class(spec.kind)
    arrays = cls.build(spec, library, CollectingEmitter(), lambda: False)
    arrays.update(cls.quality_reference_of(library, arrays).to_arrays())
    arrays.update(foot_floor_arrays(library, cls.example_clips(library, arrays)))
    arrays.update(library_to_arrays(library))
    return cls(library, arrays)


def curve(
    engine: Engine, request_data: dict[str, Any], bound: int | None, default: int | None
) -> dict[str, Any]:
    """One search with work bound ``bound`` (and a 600-s cap): the convergence figures."""
    field, metric = WORK[engine.name]
    data = dict(request_data, budget_s=600)
    if bound is not None and field != "stages":
        data[field] = bound
    request = parse_job_request(data)
    rec = CpuEmitter()
    t0, c0 = time.perf_counter(), time.process_time()
    engine.search(request, Run(600.0, emit=rec))
    total, cpu = time.perf_counter() - t0, time.process_time() - c0
    points = [
        [int(s.metrics.get(metric, i + 1)), round(float(s.score), 5), round(t, 3), round(c - c0, 3)]
        for i, (s, t, c) in enumerate(zip(rec.solutions, rec.times, rec.cpu, strict=True))
        if not s.metrics.get("alternative")
    ]
    final = points[-1]
    out: dict[str, Any] = {
        "engine": engine.name,
        "work": field,
        "default": default,
        "curve": points,
        "final": {"unit": final[0], "score": final[1], "seconds": final[2], "cpu_s": final[3]},
        "search_s": round(total, 3),
        "search_cpu_s": round(cpu, 3),
    }
    for pct in (1, 5):
        hit = next(p for p in points if p[1] <= final[1] + abs(final[1]) * pct / 100 + 1e-12)
        out[f"within_{pct}pct"] = [hit[0], hit[2], hit[3]]
    if default is not None:
        at = [p for p in points if p[0] <= default]
        out["at_default"] = [at[-1][1], at[-1][2], at[-1][3]] if at else None
    return out


class CpuEmitter(CollectingEmitter):
    """A :class:`CollectingEmitter` that also notes the process CPU time of every solution."""

    def __init__(self) -> None:
        super().__init__()
        self.cpu: list[float] = []

    def solution(self, solution: Any) -> str:
        self.cpu.append(time.process_time())
        return super().solution(solution)


def bandai_graph() -> dict[str, Any] | None:
    if not BANDAI.exists():
        return None
    files: list[str] = []
    for kind, k in (("walk", 10), ("walk-turn-left", 10), ("walk-turn-right", 10), ("run", 5)):
        files += sorted(glob.glob(str(BANDAI / f"dataset-2_{kind}_normal_*.bvh")))[:k]
    return {"kind": "graph", "clips": [{"bvh": f} for f in files]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=400, help="graph rounds searched (the curve's end)")
    ap.add_argument("--passes", type=int, default=200, help="annotation passes searched")
    ap.add_argument("--only", nargs="*", default=None, help="examples to run (default: all)")
    args = ap.parse_args(argv)
    tune_process()
    from schemas.annotations import AnnotationRequest
    from schemas.graph import GraphRequest

    g_default = GraphRequest.model_fields["rounds"].default
    a_default = (
        AnnotationRequest.model_fields["passes"].default
        if "passes" in AnnotationRequest.model_fields
        else None
    )
    out: dict[str, Any] = {}
    want = set(args.only) if args.only else None
    if want is None or "graph_readme" in want:
        out["graph_readme"] = curve(load_engine(GRAPH_SPEC), GRAPH_REQUEST, args.rounds, g_default)
    if (want is None or "graph_bandai" in want) and (spec := bandai_graph()) is not None:
        req = {
            "engine": "graph",
            "frames": 300,
            "seed": 1,
            "constraints": [
                {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
                {"type": "body", "frame": 299, "position": [6.0, 0.0], "heading_deg": 90.0},
            ],
        }
        out["graph_bandai"] = curve(load_engine(spec), req, args.rounds, g_default)
    if want is None or "annotations_readme" in want:
        out["annotations_readme"] = curve(
            load_engine(ANNOTATED_SPEC), ANNOTATION_REQUEST, args.passes, a_default
        )
    out["load"] = round(os.getloadavg()[0], 2)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
