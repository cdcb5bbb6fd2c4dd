"""The live control session: latency per frame and error against the offline result (CMU salsa).

Usage: ``python bench/control_live.py [--held 07,10] [--latency 1,1.5,2,3] [--chunk 3] [--cache DIR]``
from the project root (needs ../shared/data/cmu-salsa).

For each held-out dance (leave-one-dance-out database, the held-out couple moved rigidly as in
``bench/control_salsa.py``), the moved leader's control joints are streamed into
:class:`engines.control.session.LiveControl` ``--chunk`` frames per message at the database rate
(30 Hz), as a client on the WebSocket would, for each ``--latency``. Measured:

* ``push_ms``: compute time of one message (median, 95th percentile, max) — what a frame waits on
  top of the stated latency; ``frame_latency_ms``: stated latency + the compute time of the message
  that releases the frame (median, 95th percentile, max over frames); ``realtime_ok``: every message
  was handled within the time its frames last (``chunk / 30`` s);
* ``solve_ms``: median time of one window's DP + re-timing; ``solves``;
* ``error_x_height``: the live follower's error against the real follower (the acceptance check's
  figure); ``vs_offline_x_height``: mean distance of its hip, head, hands and feet to the offline
  engine's output for the same leader; ``offline_error_x_height``: the offline output's error.

Prints one JSON object (progress on stderr). Timings are on a shared machine: medians.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from control_salsa import POINTS, SALSA, engine_for, follower_errors, held_dances, moved  # noqa: E402

from engines.base import CollectingEmitter, Run  # noqa: E402
from engines.control.engine import ControlEngine  # noqa: E402
from engines.control.session import LiveControl  # noqa: E402
from engines.registry import parse_job_request  # noqa: E402
from motion import Motion  # noqa: E402
from motion.allocator import tune_process  # noqa: E402
from motion.bvh import bvh_text, parse_bvh  # noqa: E402
from motion.resample import resample  # noqa: E402


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def stream(
    session: LiveControl, cloud: np.ndarray, chunk: int
) -> tuple[Motion, list[float], list[float], int]:
    """Push ``cloud (F, P, 3)`` ``chunk`` frames at a time, then finish. Returns the target motion,
    the compute time of every message (s), per target frame the compute time of the message that
    released it (s), and the most frames the session was ever behind its stated latency."""
    roots, rots, push_s, frame_wait = [], [], [], []
    behind = 0
    steps = [cloud[i : i + chunk] for i in range(0, cloud.shape[0], chunk)]
    for k, frames in enumerate([*steps, None]):
        t0 = time.perf_counter()
        msg = session.push(frames) if frames is not None else session.finish()
        dt = time.perf_counter() - t0
        if frames is not None:
            push_s.append(dt)
            behind = max(behind, session.received - session.latency - session.frame)
        n = len(msg["root"])
        if n and frames is not None:
            frame_wait += [dt] * n
        roots.append(np.asarray(msg["root"], dtype=np.float64).reshape(-1, 3))
        if n:
            rots.append(np.asarray(msg["rotations"], dtype=np.float64))
        del k
    base = session.engine.target_motion(session.db.pairs[0][1])[0]
    root = np.concatenate(roots)
    motion = replace(
        base,
        root_positions=root / base.metres_per_unit,
        rotations=np.concatenate(rots),
        joint_translations=np.repeat(base.joint_translations[:1], root.shape[0], 0),
        fps=session.fps,
        name="live",
    )
    return motion, push_s, frame_wait, behind


def points_of(motion: Motion) -> np.ndarray:
    pos = motion.global_positions() * motion.metres_per_unit
    return np.asarray(pos[:, [motion.skeleton.names.index(n) for n in POINTS]])


def offline(engine: ControlEngine, leader: Motion) -> Motion:
    request = parse_job_request({"engine": "control", "control": {"bvh": "lead.bvh"}})
    request.attach_inputs({"lead.bvh": bvh_text(leader).encode()})
    out = CollectingEmitter()
    engine.search(request, Run(request.budget_s, emit=out))
    return min(out.solutions, key=lambda s: s.score).motion


def pct(values: list[float], q: float) -> float:
    return round(float(np.percentile(values, q)) * 1000, 2) if values else 0.0


def run(held: str, latencies: list[float], chunk: int, cache: Path | None) -> dict[str, Any]:
    engine, _ = engine_for(held, cache)
    leader = moved(parse_bvh((SALSA / f"60_{held}_scaled.bvh").read_bytes()), 25.0, 0.8, -1.1)
    follower = moved(parse_bvh((SALSA / f"61_{held}_scaled.bvh").read_bytes()), 25.0, 0.8, -1.1)
    ref = offline(engine, leader)
    lead30 = resample(leader, engine.db.fps)
    pos = lead30.global_positions() * lead30.metres_per_unit
    cloud = pos[:, [lead30.skeleton.names.index(j) for j in engine.db.meta["control_joints"]]]
    height = float(pos[:, lead30.skeleton.names.index("head"), 1].max())
    ref_pts = points_of(resample(ref, engine.db.fps))
    result: dict[str, Any] = {
        "offline_error_x_height": follower_errors(ref, follower, leader)["error_x_height"]
    }
    for lat in latencies:
        session = LiveControl(engine, latency_s=lat)
        out, push_s, wait, behind = stream(session, cloud, chunk)
        n = min(out.num_frames, ref_pts.shape[0])
        vs = float(np.linalg.norm(points_of(out)[:n] - ref_pts[:n], axis=-1).mean() / height)
        budget = chunk / engine.db.fps
        entry = {
            "latency_s": session.latency_s,
            "frames": out.num_frames,
            "control_frames": int(cloud.shape[0]),
            "error_x_height": follower_errors(out, follower, leader)["error_x_height"],
            "vs_offline_x_height": round(vs, 4),
            "push_ms": {"median": pct(push_s, 50), "p95": pct(push_s, 95), "max": pct(push_s, 100)},
            "frame_latency_ms": {
                "median": round(session.latency_s * 1000 + pct(wait, 50), 1),
                "p95": round(session.latency_s * 1000 + pct(wait, 95), 1),
                "max": round(session.latency_s * 1000 + pct(wait, 100), 1),
            },
            "realtime_ok": bool(max(push_s) <= budget),
            "max_frames_behind_latency": int(behind),
            "solve_ms_median": pct(session.solve_s, 50),
            "solves": session.solves,
        }
        log(f"dance {held} latency {lat}: {json.dumps(entry)}")
        result[f"{lat:g}"] = entry
    return result


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--held", default="07", help="held-out dances, comma separated")
    ap.add_argument("--latency", default="1,1.5,2,3", help="latencies to compare, seconds, comma separated")
    ap.add_argument("--chunk", type=int, default=3, help="control frames per message")
    ap.add_argument("--cache", type=Path, default=None, help="directory to keep built databases in")
    args = ap.parse_args(argv)
    tune_process()
    if not SALSA.exists():
        print(json.dumps({"error": f"{SALSA} not found"}))
        return 1
    held = held_dances(ap, args.held)
    try:
        latencies = [float(v) for v in args.latency.split(",")]
    except ValueError:
        ap.error(f"--latency takes numbers, got {args.latency!r}")
    if args.chunk < 1:
        ap.error("--chunk must be at least 1")
    dances = {h: run(h, latencies, args.chunk, args.cache) for h in held}
    print(
        json.dumps(
            {"chunk": args.chunk, "dances": dances, "load_avg": [round(x, 2) for x in os.getloadavg()]}
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
