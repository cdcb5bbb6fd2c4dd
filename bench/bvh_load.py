"""Benchmark: BVH parse + forward kinematics.

Prints one JSON object: ``{"file", "frames", "joints", "parse_s", "fk_s", "joint_frames_per_s"}``
where the times are medians over ``--runs`` runs and ``joint_frames_per_s = frames * joints /
(parse_s + fk_s)``. Default file: the bundled CMU salsa leader sample (or ``--file``).
Runs with the allocator tuning every Segue process applies (``motion.allocator``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from motion import read_bvh
from motion.allocator import tune_process
from motion.samples import sample_path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--file", help="BVH file (.bvh or .bvh.gz); default: bundled salsa leader")
    ap.add_argument("--runs", type=int, default=31, help="timed runs (median reported)")
    args = ap.parse_args(argv)
    tune_process()  # as in every Segue process (see motion/allocator.py)
    path = Path(args.file) if args.file else sample_path("salsa-leader")
    read_bvh(path).global_positions()  # warm caches (imports, page cache)
    parse_t, fk_t = [], []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        motion = read_bvh(path, units="m")
        t1 = time.perf_counter()
        motion.global_positions()
        t2 = time.perf_counter()
        parse_t.append(t1 - t0)
        fk_t.append(t2 - t1)
    parse_s, fk_s = statistics.median(parse_t), statistics.median(fk_t)
    out = {
        "file": str(path),
        "frames": motion.num_frames,
        "joints": motion.num_joints,
        "parse_s": round(parse_s, 6),
        "fk_s": round(fk_s, 6),
        "joint_frames_per_s": round(motion.num_frames * motion.num_joints / (parse_s + fk_s)),
    }
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
