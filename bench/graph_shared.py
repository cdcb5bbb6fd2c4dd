"""Benchmark: two characters with shared constraints in the graph engine (engines.graph.coupled).

Builds a graph database from the bundled CMU walks (``sample:walk-05-01``, ``walk-10-04``,
``walk-12-02``, ``walk``: 30 fps, no ../shared needed) and runs, for each seed, two requests of
two walkers:

* ``high-five``: walkers 6 m apart head for each other, 0.8 m to the side; their right hands meet
  at frame 75 and their bodies stay 0.5 m apart before frame 65 and from frame 85;
* ``pass``: the same walkers pass each other at frame 75, bodies 0.9 m apart (a body-to-body
  meet), and stay 0.5 m apart throughout.

Every figure is measured on the returned (combined) motion by forward kinematics of its joints,
not taken from the report: ``meet_error_cm`` (distance at the frame minus the wanted distance),
``min_separation_cm`` and its frame (over each apart constraint's range), and whether the report's
figures agree (``report_agrees``). Prints one JSON object: per run ``{"request", "seed",
"meet_error_cm", "min_separation_cm", "ok", "report_agrees", "passes", "search_s"}`` and the
summary (mean and worst meet error, worst separation shortfall, mean time per request).

Options: ``--rounds`` (coupling rounds), ``--meet-weight`` (:data:`engines.graph.coupled.MEET_WEIGHT`),
``--budget`` per request, ``--seeds``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engines.base import CollectingEmitter, Run, foot_floor_arrays
from engines.graph import shared as shared_module
from engines.graph.build import build_graph
from engines.graph.engine import GraphEngine
from engines.library import ClipInput, build_library
from engines.registry import parse_database_spec, parse_job_request
from motion.samples import sample_path

CLIPS = ("walk-05-01", "walk-10-04", "walk-12-02", "walk")


def engine() -> GraphEngine:
    """A graph database of the bundled walks, as a build stores it."""
    spec = parse_database_spec({"kind": "graph", "clips": [{"bvh": f"sample:{c}", "name": c} for c in CLIPS]})
    library = build_library([ClipInput(c, sample_path(c).read_bytes()) for c in CLIPS], spec.fps)
    arrays = build_graph(spec, library, CollectingEmitter(), lambda: False)
    arrays.update(GraphEngine.quality_reference_of(library, arrays).to_arrays())
    arrays.update(foot_floor_arrays(library, GraphEngine.example_clips(library, arrays)))
    return GraphEngine(library, arrays)


def walkers() -> list[dict[str, Any]]:
    return [
        {"constraints": [{"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 90.0}]},
        {"constraints": [{"type": "body", "frame": 0, "position": [6.0, 0.8], "heading_deg": -90.0}]},
    ]


REQUESTS: dict[str, list[dict[str, Any]]] = {
    "high-five": [
        {
            "type": "meet",
            "frame": 75,
            "a": {"character": 0, "joint": "rHand"},
            "b": {"character": 1, "joint": "rHand"},
        },
        {"type": "apart", "a": {"character": 0}, "b": {"character": 1}, "min_m": 0.5, "end": 65},
        {"type": "apart", "a": {"character": 0}, "b": {"character": 1}, "min_m": 0.5, "start": 85},
    ],
    "pass": [
        {"type": "meet", "frame": 75, "a": {"character": 0}, "b": {"character": 1}, "distance_m": 0.9},
        {"type": "apart", "a": {"character": 0}, "b": {"character": 1}, "min_m": 0.5},
    ],
}


def point(pos: np.ndarray[Any, Any], names: tuple[str, ...], p: dict[str, Any]) -> np.ndarray[Any, Any]:
    """``(F, 3)`` a request point on the output: the joint, or the hips on the floor."""
    c = p["character"]
    if p.get("joint"):
        return np.asarray(pos[:, names.index(f"c{c}_{p['joint']}")])
    hips = pos[:, names.index(f"c{c}_hip")]
    return np.stack((hips[:, 0], np.zeros(len(hips)), hips[:, 2]), axis=-1)


def distance(pos: np.ndarray[Any, Any], names: tuple[str, ...], c: dict[str, Any]) -> np.ndarray[Any, Any]:
    d = point(pos, names, c["a"]) - point(pos, names, c["b"])
    if not (c["a"].get("joint") and c["b"].get("joint")):
        d = d[:, [0, 2]]
    return np.asarray(np.linalg.norm(d, axis=-1))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--budget", type=float, default=10.0)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--meet-weight", type=float, default=shared_module.MEET_WEIGHT)
    ap.add_argument("--requests", nargs="*", default=sorted(REQUESTS))
    args = ap.parse_args(argv)
    shared_module.MEET_WEIGHT = args.meet_weight
    eng = engine()
    runs: list[dict[str, Any]] = []
    for name in args.requests:
        for seed in range(1, args.seeds + 1):
            body = {
                "engine": "graph",
                "frames": 150,
                "seed": seed,
                "budget_s": args.budget,
                "coupling_rounds": args.rounds,
                "characters": walkers(),
                "shared": REQUESTS[name],
            }
            request = parse_job_request(body)
            rec = CollectingEmitter()
            t0 = time.perf_counter()
            eng.search(request, Run(args.budget, emit=rec))
            elapsed = time.perf_counter() - t0
            best = rec.best
            if best is None or best.quality is None:
                runs.append({"request": name, "seed": seed, "error": "no solution"})
                continue
            m = best.motion
            pos = m.global_positions() * m.metres_per_unit
            names = m.skeleton.names
            meet_err: list[float] = []
            sep: list[float] = []
            agrees = True
            for i, c in enumerate(REQUESTS[name]):
                d = distance(pos, names, c)
                e = best.quality.constraint_errors[f"shared[{i}]"]
                if c["type"] == "meet":
                    err = 100 * abs(float(d[c["frame"]]) - c.get("distance_m", 0.0))
                    meet_err.append(err)
                    agrees &= abs(err - e["error_cm"]) < 0.01
                else:
                    lo, hi = c.get("start", 0), c.get("end", len(d))
                    s = 100 * float(d[lo:hi].min())
                    sep.append(s - 100 * c["min_m"])
                    agrees &= abs(s - e["min_distance_cm"]) < 0.01
            runs.append(
                {
                    "request": name,
                    "seed": seed,
                    "meet_error_cm": round(max(meet_err), 2),
                    "min_separation_margin_cm": round(min(sep), 2),
                    "ok": best.quality.ok,
                    "report_agrees": bool(agrees),
                    "passes": best.metrics.get("coupling_passes"),
                    "search_s": round(elapsed, 2),
                    "reasons": best.quality.reasons,
                }
            )
    good = [r for r in runs if "meet_error_cm" in r]
    errs = [r["meet_error_cm"] for r in good]
    out = {
        "rounds": args.rounds,
        "meet_weight": args.meet_weight,
        "budget_s": args.budget,
        "runs": runs,
        "meet_error_cm_mean": round(float(np.mean(errs)), 2) if errs else None,
        "meet_error_cm_max": round(float(np.max(errs)), 2) if errs else None,
        "meet_within_5cm": f"{sum(e <= 5.0 for e in errs)}/{len(errs)}",
        "separation_margin_cm_worst": round(min(r["min_separation_margin_cm"] for r in good), 2)
        if good
        else None,
        "ok": f"{sum(bool(r['ok']) for r in good)}/{len(runs)}",
        "search_s_mean": round(float(np.mean([r["search_s"] for r in good])), 2) if good else None,
    }
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
