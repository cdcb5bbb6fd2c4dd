"""Where the control engine's salsa follower error comes from: oracle bounds on the engine's own output.

Usage: ``python bench/control_oracle.py [--held 09,10] [--jobs 2] [--cache DIR]`` from the project
root (needs ../shared/data/cmu-salsa). The protocol of ``bench/control_salsa.py`` (leave-one-dance-out
database, held-out couple rotated by 25 degrees and moved by (0.8, -1.1)); the engine runs with its
defaults, then its output is taken apart against the real follower. Every figure is a mean distance
divided by the leader's standing height, like the acceptance check's.

Per dance:

* ``error``: the check's figure on the output (hip, head, hands and feet, every output frame);
* ``edges`` / ``middle``: the same over the first and last 3 s of the dance, and over the rest;
* ``in_contact`` / ``apart``: over the frames where the *real* couple's nearest hands are within
  0.2 m, and over the others (``contact_fraction``: the share of the first kind);
* the output's segments re-measured at the database rate on the database's target joints
  (``segments``: the same error on those points, the reference for the two bounds below):

  - ``best_translation``: each segment moved on the floor by the translation that brings it
    nearest the real follower (its pose, timing and heading kept): what perfect placement of the
    chosen examples would give;
  - ``best_instance``: for each segment's window of the leader, the database instance (stretched to
    the window, placed by its own alignment to the leader, as the engine places it) nearest the real
    follower: what a perfect choice among the database's instances would give with the engine's
    segmentation and alignment; ``best_instance_rank``: the median rank of that instance among all
    instances by interpretation distance (0 = the leader's best match).

Prints one JSON object on stdout (progress on stderr): ``{"dances": {"07": {...}}, "mean": {...},
"load_avg": [...]}``. The bounds use the truth, so no method reaches them; they say how much of
the error is placement, how much choice, and whether the leader's motion singles the right choice out.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from control_salsa import POINTS, SALSA, engine_for, held_dances, log, moved, synthesize  # noqa: E402

from engines.control.dp import align_points, paired_alignment, stretched_templates  # noqa: E402
from engines.control.engine import ControlEngine  # noqa: E402
from engines.control.points import resample_cloud, sample_cloud  # noqa: E402
from motion import Motion  # noqa: E402
from motion.allocator import tune_process  # noqa: E402
from motion.bvh import parse_bvh  # noqa: E402

Array = npt.NDArray[np.float64]

EDGE_S = 3.0
"""Length of the dance's opening and closing (seconds) reported apart from the middle."""
CONTACT_M = 0.2
"""The real partners' nearest hands closer than this count as in contact (the databases' default)."""


def joint_points(motion: Motion, names: list[str] | tuple[str, ...]) -> Array:
    """``(F, len(names), 3)`` metres: the named joints' world positions."""
    pos = motion.global_positions() * motion.metres_per_unit
    return np.asarray(pos[:, [motion.skeleton.names.index(n) for n in names]])


def nearest_frames(out: Motion, other: Motion) -> npt.NDArray[np.intp]:
    """``(F,)`` for each frame of ``out``, the frame of ``other`` nearest in time (the check's pairing)."""
    frames = np.round(np.arange(out.num_frames) * other.fps / out.fps).astype(np.intp)
    return np.asarray(np.clip(frames, 0, other.num_frames - 1))


def output_split(out: Motion, follower: Motion, leader: Motion, height: float) -> dict[str, float]:
    """The check's error of ``out`` over all frames, the dance's edges and middle, and the frames
    where the real couple is in hand contact or apart."""
    o = joint_points(out, POINTS)
    g = joint_points(follower, POINTS)[nearest_frames(out, follower)]
    li = nearest_frames(out, leader)
    per_frame = np.linalg.norm(o - g, axis=-1).mean(axis=1) / height
    edge = int(round(EDGE_S * out.fps))
    edges = np.zeros(out.num_frames, dtype=bool)
    edges[:edge] = edges[-edge:] = True
    lead_hands = joint_points(leader, ("rHand", "lHand"))[li]
    gap = np.linalg.norm(g[:, 2:4, None] - lead_hands[:, None], axis=-1).min(axis=(1, 2))
    contact = gap < CONTACT_M

    def mean(mask: npt.NDArray[np.bool_]) -> float:
        return float(per_frame[mask].mean()) if mask.any() else float("nan")

    return {
        "error": float(per_frame.mean()),
        "edges": mean(edges),
        "middle": mean(~edges),
        "in_contact": mean(contact),
        "apart": mean(~contact),
        "contact_fraction": float(contact.mean()),
    }


def segment_bounds(
    engine: ControlEngine, solution: Any, leader_cloud: Array, follower_cloud: Array, height: float
) -> dict[str, float]:
    """The output's segments at the database rate: their error on the target joints as placed, with
    the best floor translation, and with the best instance of the database (see the module doc)."""
    inst = engine.solver_instances_
    fps = engine.db.fps
    target = engine.db.target
    every = np.arange(inst.count)
    placed_err, moved_err, best_err, ranks, weights = [], [], [], [], []
    for seg in solution.annotations["segments"]:
        a = int(round(seg["start_s"] * fps))
        b = min(int(round((seg["start_s"] + seg["duration_s"]) * fps)), leader_cloud.shape[0])
        d = b - a
        if d < 2:
            continue
        window = leader_cloud[a:b]
        truth = follower_cloud[a:b]
        templates = stretched_templates(inst, every, d, fps)  # (N, d, Pc, 3)
        res, cos, sin, tx, tz = paired_alignment(
            np.broadcast_to(window.reshape(1, -1, 3), (inst.count, d * window.shape[1], 3)),
            templates.reshape(inst.count, -1, 3),
        )
        src = inst.start[:, None] + inst.length[:, None] * (np.arange(d) / d)[None, :]
        placed = align_points(sample_cloud(target, src).reshape(inst.count, -1, 3), cos, sin, tx, tz)
        placed = placed.reshape(inst.count, d, -1, 3)
        errors = np.linalg.norm(placed - truth[None], axis=-1).mean(axis=(1, 2)) / height
        chosen = int(engine.local_of_[seg["instance"]])
        shift = (truth - placed[chosen]).mean(axis=(0, 1))
        shift[1] = 0.0
        best = int(np.argmin(errors))
        placed_err.append(float(errors[chosen]))
        moved_err.append(float(np.linalg.norm(placed[chosen] + shift - truth, axis=-1).mean() / height))
        best_err.append(float(errors[best]))
        ranks.append(int((res < res[best]).sum()))
        weights.append(d)
    w = np.asarray(weights, dtype=np.float64) / float(np.sum(weights))
    return {
        "segments": float(np.dot(w, placed_err)),
        "best_translation": float(np.dot(w, moved_err)),
        "best_instance": float(np.dot(w, best_err)),
        "best_instance_rank": float(np.median(ranks)),
    }


def run_dance(job: tuple[str, str | None]) -> tuple[str, dict[str, float]]:
    """One held-out dance: synthesize with the defaults, then every figure of the module doc."""
    held, cache = job
    engine, _ = engine_for(held, None if cache is None else Path(cache))
    leader = moved(parse_bvh((SALSA / f"60_{held}_scaled.bvh").read_bytes()), 25.0, 0.8, -1.1)
    follower = moved(parse_bvh((SALSA / f"61_{held}_scaled.bvh").read_bytes()), 25.0, 0.8, -1.1)
    height = float(joint_points(leader, ("head",))[:, 0, 1].max())
    solution, _ = synthesize(engine, leader, {}, None)
    figures = output_split(solution.motion, follower, leader, height)
    db = engine.db
    leader_cloud = resample_cloud(joint_points(leader, db.meta["control_joints"]), leader.fps, db.fps)
    follower_cloud = resample_cloud(joint_points(follower, db.meta["target_joints"]), follower.fps, db.fps)
    figures.update(segment_bounds(engine, solution, leader_cloud, follower_cloud, height))
    rounded = {k: round(v, 4) for k, v in figures.items()}
    log(f"dance {held}: {json.dumps(rounded)}")
    return held, rounded


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--held", default=None, help="held-out dances, comma separated (default: all 14)")
    ap.add_argument("--jobs", type=int, default=1, help="dances run in parallel processes")
    ap.add_argument("--cache", type=Path, default=None, help="directory to keep built databases in")
    args = ap.parse_args(argv)
    tune_process()
    if not SALSA.exists():
        print(json.dumps({"error": f"{SALSA} not found"}))
        return 1
    held = held_dances(ap, args.held)
    if args.jobs < 1:
        ap.error("--jobs must be at least 1")
    cache = None if args.cache is None else str(args.cache.resolve())
    jobs = [(h, cache) for h in held]
    if args.jobs == 1:
        results = [run_dance(job) for job in jobs]
    else:
        with Pool(min(args.jobs, len(jobs)), initializer=tune_process) as pool:
            results = pool.map(run_dance, jobs, chunksize=1)
    dances = dict(sorted(results))
    keys = next(iter(dances.values())).keys()
    mean = {k: round(float(np.nanmean([d[k] for d in dances.values()])), 4) for k in keys}
    print(json.dumps({"dances": dances, "mean": mean, "load_avg": [round(x, 2) for x in os.getloadavg()]}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
