"""Benchmark: the motion-graph engine on Bandai-Namco locomotion (needs ../shared/data).

Builds a graph database from dataset-2 walks, turns and runs at 30 fps, then searches for a
``--frames``-frame motion from ([0, 0], 0 deg) to a body constraint ``--goal x z heading`` for
``--budget`` seconds, and prints one JSON object:

``{"frames_db", "clips", "leaf_edges", "root_edges", "build_s", "first_solution_ms", "stopped",
"within_5pct_s", "score_at_1s", "final_score", "position_error_cm", "heading_error_deg",
"length_frames", "foot_slip_m_s", "foot_slip_sources_m_s", "solutions", "search_s", "ok", "reasons"}``

The search does ``--rounds`` rounds (the request's default, 15, when not given; it stops earlier
when it converges) under a ``--budget`` cap; ``stopped`` says which ended it (``work`` or
``budget``). ``within_5pct_s`` is the time of the first solution whose score is within 5% of the
final best; ``score_at_1s`` the best score emitted within 1 s.
``foot_slip_m_s`` is :func:`motion.metrics.foot_slip` of the output (contacts detected on it);
``foot_slip_sources_m_s`` the same metric on the database clips (frame-weighted mean), for scale;
``search_s`` when the last solution was emitted (the search stops once it converges); ``ok`` and
``reasons`` the best result's quality report.
"""

from __future__ import annotations

import argparse
import glob
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engines.base import CollectingEmitter, Run, foot_floor_arrays  # noqa: E402
from engines.graph.build import build_graph  # noqa: E402
from engines.graph.engine import GraphEngine  # noqa: E402
from engines.library import ClipInput, build_library  # noqa: E402
from engines.registry import parse_database_spec, parse_job_request  # noqa: E402
from motion.allocator import tune_process  # noqa: E402
from motion.ground import body_root, heading  # noqa: E402
from motion.metrics import foot_slip  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "bandai-namco" / "dataset-2"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--per-kind", type=int, default=10, help="clips of each kind (walk, turns, run/2)")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--goal", type=float, nargs=3, default=[6.0, 0.0, 90.0], metavar=("X", "Z", "HEADING"))
    ap.add_argument("--budget", type=float, default=60.0, help="time cap, seconds")
    ap.add_argument("--rounds", type=int, default=None, help="search rounds (default: the request's)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--candidates", default="auto", choices=("auto", "indexed", "all_pairs"), help="the spec's candidates"
    )
    args = ap.parse_args(argv)
    tune_process()
    if not DATA.exists():
        print(json.dumps({"error": f"{DATA} not found"}))
        return 1
    files: list[str] = []
    for kind, k in (
        ("walk", args.per_kind),
        ("walk-turn-left", args.per_kind),
        ("walk-turn-right", args.per_kind),
        ("run", args.per_kind // 2),
    ):
        files += sorted(glob.glob(str(DATA / f"dataset-2_{kind}_normal_*.bvh")))[:k]
    spec = parse_database_spec(
        {"kind": "graph", "clips": [{"bvh": f} for f in files], "candidates": args.candidates}
    )
    t0 = time.perf_counter()
    library = build_library([ClipInput(Path(f).stem, Path(f).read_bytes()) for f in files], spec.fps)
    arrays = build_graph(spec, library, CollectingEmitter(), lambda: False)
    # what a database build stores beside the graph: the examples' quality reference and foot heights
    arrays.update(GraphEngine.quality_reference_of(library, arrays).to_arrays())
    arrays.update(foot_floor_arrays(library, GraphEngine.example_clips(library, arrays)))
    build_s = time.perf_counter() - t0
    report: dict[str, Any] = json.loads(str(arrays["graph.report"]))
    engine = GraphEngine(library, arrays)
    x, z, h = args.goal
    request = parse_job_request(
        {
            "engine": "graph",
            "frames": args.frames,
            "seed": args.seed,
            "budget_s": args.budget,
            **({} if args.rounds is None else {"rounds": args.rounds}),
            "constraints": [
                {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
                {"type": "body", "frame": args.frames - 1, "position": [x, z], "heading_deg": h},
            ],
        }
    )
    rec = CollectingEmitter()
    stopped = engine.search(request, Run(args.budget, emit=rec))
    events = [(t, float(sol.score), sol) for t, sol in zip(rec.times, rec.solutions, strict=True)]
    if not events:
        print(json.dumps({"error": "no solution"}))
        return 1
    best_t, best_score, best = min(events, key=lambda e: e[1])
    within = next(t for t, s, _ in events if s <= best_score * 1.05 + 1e-12)
    at_1s = min((s for t, s, _ in events if t <= 1.0), default=float("nan"))
    frames = np.array([m.num_frames for m in library.motions], dtype=np.float64)
    sources = float(np.average([foot_slip(m) for m in library.motions], weights=frames))
    motion = best.motion
    pos = motion.global_positions()
    yaw = np.degrees(heading(motion, pos))
    end = np.asarray(pos[-1, body_root(motion.skeleton), [0, 2]])
    out = {
        "candidates": report.get("candidates"),
        "frames_db": library.total_frames,
        "clips": len(library.names),
        "leaf_edges": report.get("leaf_edges"),
        "root_edges": report.get("root_edges"),
        "build_s": round(build_s, 3),
        "first_solution_ms": round(events[0][0] * 1e3, 1),
        "stopped": stopped.value,
        "within_5pct_s": round(within, 3),
        "score_at_1s": round(at_1s, 4),
        "final_score": round(best_score, 4),
        "position_error_cm": round(float(np.linalg.norm(end - [x, z])) * 100, 2),
        "heading_error_deg": round(float(abs((yaw[-1] - h + 180) % 360 - 180)), 2),
        "length_frames": motion.num_frames,
        "foot_slip_m_s": round(foot_slip(motion, pos), 4),
        "foot_slip_sources_m_s": round(sources, 4),
        "solutions": len(events),
        "search_s": round(events[-1][0], 3),
        "ok": None if best.quality is None else best.quality.ok,
        "reasons": [] if best.quality is None else best.quality.reasons,
    }
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
