"""Benchmark: do time-scaled copies of the clips help the graph engine? One JSON line per library.

Needs ``../shared/data/bandai-namco``. Each ``--libraries`` entry is built in this process as a
worker builds it (``bench.graph_scale.build_arrays``: graph, quality reference, foot floor) and
asked for each request below, once per ``--seeds`` seed (15 rounds, as any request):

* ``real``: every clip of both sets (639 clips, 85,981 frames at 30 fps);
* ``speeds``: the same plus a copy of each played at x0.9 and x1.1 (resampled to 30 fps: a graph
  spec's ``"speeds": [0.9, 1.1]``, :func:`engines.library.with_speeds`);
* ``mirror``: the same plus each clip's mirror image (as a spec's ``mirror``);
* ``half``, ``half_mirror``, ``half_mirror_speeds``: every 2nd clip, plus mirror images, plus both
  time-scaled (x0.9, x1.1) too (mirror + speeds within the frame budget).

Requests (origin, heading 0, to a body goal): ``far`` 12 m at heading 90 in 20 s (issue 27's);
``near0/90/180`` 5 m ahead at heading 0, 90, 180 in 20 s; ``brisk``, ``jog``, ``slow`` 15, 25
and 3 m at heading 0 in 10 s; ``graphpy`` bench/graph.py's request (6 m, heading 90, 300 frames).
Per request and seed:
``err_cm`` (body root to the goal), ``score``, ``ok``, ``reasons``, and the quality report's
``foot_slide`` (m/s), ``root_speed`` and ``root_speed_p99`` values (m/s); per library ``frames``,
``build_cpu_s`` and ``search_cpu_s`` (process CPU). Run with ``nice -n 10``, one library at a time.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

REQUESTS = {
    "far": (12.0, 0.0, 90.0, 600),
    "near0": (5.0, 0.0, 0.0, 600),
    "near90": (5.0, 0.0, 90.0, 600),
    "near180": (5.0, 0.0, 180.0, 600),
    "brisk": (15.0, 0.0, 0.0, 300),
    "jog": (25.0, 0.0, 0.0, 300),
    "slow": (3.0, 0.0, 0.0, 300),
    "graphpy": (6.0, 0.0, 90.0, 300),
}
FIGURES = ("foot_slide", "root_speed", "root_speed_p99")


def library(kind: str) -> Any:
    from graph_scale import library_of, subset

    from engines.library import with_mirrors, with_speeds

    lib, _ = library_of(85981)
    if kind.startswith("half"):
        lib = subset(lib, 2)
    if "mirror" in kind:
        lib = with_mirrors(lib)
    if "speeds" in kind:
        lib = with_speeds(lib, [0.9, 1.1])  # as a graph spec's "speeds": [0.9, 1.1] does
    return lib


def run(kind: str, seeds: list[int]) -> dict[str, Any]:
    from graph_scale import body_goal_request, build_arrays
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    from engines.base import CollectingEmitter
    from engines.graph.engine import GraphEngine
    from engines.library import library_from_arrays
    from engines.registry import parse_job_request
    from motion.allocator import tune_process
    from motion.ground import body_root

    tune_process()
    out: dict[str, Any] = {"library": kind, "load_avg": round(os.getloadavg()[0], 2)}
    lib = library(kind)
    arrays, figures = build_arrays(lib, "indexed")
    out.update({k: figures[k] for k in ("frames", "clips", "build_cpu_s", "leaf_edges", "dropped_frames")})
    engine = GraphEngine(library_from_arrays(arrays), arrays)
    c_all = time.process_time()
    results: dict[str, Any] = {}
    for name, (x, z, h, n) in REQUESTS.items():
        rows = []
        for seed in seeds:
            request = parse_job_request(body_goal_request(n, seed, 300.0, (x, z, h)))
            rec = CollectingEmitter()
            c0 = time.process_time()
            with threadpool_limits(limits=1, user_api="blas"):
                engine.searcher(seed).run(request, 300.0, rec, lambda: False)
            best = min(rec.solutions, key=lambda s: float(s.score))
            pos = best.motion.global_positions() * best.motion.metres_per_unit
            end = np.asarray(pos[-1, body_root(best.motion.skeleton), [0, 2]])
            q = best.quality
            plaus = {} if q is None else q.plausibility
            rows.append(
                {
                    "seed": seed,
                    "err_cm": round(float(np.linalg.norm(end - [x, z])) * 100, 1),
                    "score": round(float(best.score), 3),
                    "ok": None if q is None else q.ok,
                    "reasons": [] if q is None else q.reasons,
                    **{k: plaus[k].get("value") for k in FIGURES if k in plaus},
                    "cpu_s": round(time.process_time() - c0, 2),
                }
            )
        results[name] = rows
    out["search_cpu_s"] = round(time.process_time() - c_all, 1)
    out["requests"] = results
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--libraries", default="real,speeds,mirror")
    ap.add_argument("--seeds", default="1,2,3")
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    for kind in args.libraries.split(","):
        print(json.dumps(run(kind, seeds)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
