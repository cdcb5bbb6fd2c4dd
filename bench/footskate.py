"""Benchmark: foot-skate cleanup (motion.footskate) on real walks (needs ../shared/data).

For each clip: foot slip (``motion.metrics.foot_slip`` with the clip's detected contacts) before
and after :func:`motion.footskate.remove_foot_skate`, the largest joint displacement it caused,
the largest distance left between a planted joint and its target (out of reach), and the same
with ``root_adjust``; then the throughput on the Bandai-Namco clip (22 joints) tiled to
``--frames`` frames (best of ``--repeat``; wall clock and process CPU time, the latter robust to
a busy machine). Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from motion import Motion  # noqa: E402
from motion.contacts import detect_contacts  # noqa: E402
from motion.footskate import solve_foot_skate  # noqa: E402
from motion.io import load_motion  # noqa: E402
from motion.metrics import foot_slip  # noqa: E402

DATA = ROOT.parent / "shared" / "data"
CLIPS = (
    ("bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh", 0),
    ("bandai-namco/dataset-2/dataset-2_walk-turn-left_normal_001.bvh", 0),
    ("cmu-walks/007_02.bvh", 1),  # frame 0 is a T-pose
    ("cmu-daz/walks/07_09.bvh", 1),
    ("cmu-salsa/60_01_scaled.bvh", 0),
)


def measure(m: Motion) -> dict[str, Any]:
    contacts = detect_contacts(m)
    p0 = m.global_positions()
    out: dict[str, Any] = {"frames": m.num_frames, "joints": m.num_joints}
    out["slip_before_m_s"] = round(foot_slip(m, p0, contacts[1], contacts[0]), 4)
    for key, adjust in (("", False), ("root_adjust_", True)):
        res = solve_foot_skate(m, contacts, root_adjust=adjust)
        p1 = res.motion.global_positions()
        mpu = m.metres_per_unit
        out[f"{key}slip_after_m_s"] = round(foot_slip(res.motion, p1, contacts[1], contacts[0]), 4)
        out[f"{key}max_displacement_m"] = round(float(np.abs(p1 - p0).max()) * mpu, 4)
        out[f"{key}max_unreached_m"] = round(float(res.residual.max()) * mpu, 4)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=50_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    if not DATA.exists():
        print(json.dumps({"error": f"{DATA} not found"}))
        return 1
    report: dict[str, Any] = {"clips": {}}
    for rel, first in CLIPS:
        path = DATA / rel
        if path.is_file():
            report["clips"][rel] = measure(load_motion(path).slice(first))
    bandai = load_motion(DATA / CLIPS[0][0])
    reps = -(-args.frames // bandai.num_frames)
    long = replace(
        bandai,
        root_positions=np.tile(bandai.root_positions, (reps, 1)),
        rotations=np.tile(bandai.rotations, (reps, 1, 1)),
        joint_translations=np.tile(bandai.joint_translations, (reps, 1, 1)),
    )
    contacts = detect_contacts(long)
    best, best_cpu = np.inf, np.inf
    for _ in range(args.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        solve_foot_skate(long, contacts)
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    report["throughput"] = {
        "frames": long.num_frames,
        "joints": long.num_joints,
        "contact_fraction": round(float(contacts[1].mean()), 3),
        "seconds": round(best, 4),
        "frames_per_s": round(long.num_frames / best),
        "cpu_frames_per_s": round(long.num_frames / max(best_cpu, 1e-9)),
    }
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
