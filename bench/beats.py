"""Benchmark: motion-beat analysis (motion/beats.py, Kim, Park & Shin 2003).

Prints one JSON object:

- ``salsa``: per CMU salsa trial (``../shared/data/cmu-salsa``, 60_NN leader / 61_NN follower, the same
  dance), the tempo detected for each partner with the default prior (40-200 bpm) and with a salsa
  prior (``--salsa-tempo``, default 120-240 bpm: salsa music runs 150-250 bpm), the beat count, the
  duration, whether the partners agree (within 5%) under each prior, and the tempo of the couple
  analysed as one body (``detect_couple_beats``, as the paper does for its waltzing couple);
- ``speed``: ``detect_beats`` frames per second over all salsa clips (median of ``--runs`` runs per
  clip; 120 fps clips, 43 joints);
- ``accuracy`` (unless ``--no-accuracy``, and only when ``../shared/acceptance/makeup.py`` exists): the
  paper's make-up protocol as the acceptance check runs it, in-process -- a Bandai walk's gait cycle
  tiled 30 times with each cycle's duration warped by up to +-15% (``warp``) and with the moments
  inside each cycle jittered (``jitter``); errors of the beats of the warped motion against the beats
  of the regular motion mapped through the known warp, in frames (bar: max <= 1, mean <= 0.25).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from motion.allocator import tune_process  # noqa: E402
from motion.beats import detect_beats, detect_couple_beats  # noqa: E402
from motion.io import load_motion  # noqa: E402

DATA = ROOT.parent / "shared" / "data"
ACCEPTANCE = ROOT.parent / "shared" / "acceptance"
WALKS = "bandai-namco/dataset-2/dataset-2_walk_normal_{:03d}.bvh"


def salsa(prior: tuple[float, float], runs: int) -> tuple[list[dict[str, Any]], dict[str, float]]:
    folder = DATA / "cmu-salsa"
    trials = sorted({p.name[3:5] for p in folder.glob("60_*_scaled.bvh")})
    rows: list[dict[str, Any]] = []
    frames_total, seconds_total = 0, 0.0
    for trial in trials:
        row: dict[str, Any] = {"trial": trial}
        pair = []
        for role, subject in (("leader", "60"), ("follower", "61")):
            motion = load_motion(folder / f"{subject}_{trial}_scaled.bvh")
            pair.append(motion)
            times = []
            for _ in range(runs):
                t0 = time.perf_counter()
                default = detect_beats(motion)
                times.append(time.perf_counter() - t0)
            dt = statistics.median(times)
            frames_total += motion.num_frames
            seconds_total += dt
            salsa_beats = detect_beats(motion, tempo_bpm=prior)
            row[role] = {
                "bpm": round(default.bpm, 1),
                "beats": int(default.times_s.size),
                "bpm_salsa_prior": round(salsa_beats.bpm, 1),
                "duration_s": round(motion.duration_s, 2),
            }
        couple = detect_couple_beats(pair)
        row["couple"] = {"bpm": round(couple.bpm, 1), "beats": int(couple.times_s.size)}
        a, b = row["leader"], row["follower"]
        row["agree"] = bool(abs(a["bpm"] / b["bpm"] - 1.0) <= 0.05)
        row["agree_salsa_prior"] = bool(abs(a["bpm_salsa_prior"] / b["bpm_salsa_prior"] - 1.0) <= 0.05)
        rows.append(row)
    speed = {
        "frames": frames_total,
        "seconds": round(seconds_total, 3),
        "frames_per_s": round(frames_total / seconds_total, 0),
    }
    return rows, speed


def accuracy(walks: list[int], seeds: list[int]) -> list[dict[str, Any]]:
    sys.path.insert(0, str(ACCEPTANCE))
    import makeup

    out: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="segue-beats-") as tmp:
        d = Path(tmp)
        for walk in walks:
            src = str(DATA / WALKS.format(walk))
            for seed in seeds:

                def beat_frames(path: Path) -> np.ndarray:
                    motion = load_motion(path)
                    return detect_beats(motion).frames(motion.fps)

                c, (s0, _), (s1, l1), _ = makeup.make(
                    src, str(d / "reg.bvh"), str(d / "war.bvh"), reps=30, jitter=0.15, seed=seed
                )
                br, bw = beat_frames(d / "reg.bvh"), beat_frames(d / "war.bvh")
                i = np.minimum((br // c).astype(int), len(s0) - 1)
                expected = s1[i] + (br - s0[i]) / c * l1[i]
                inner = bw[(bw > s1[1]) & (bw < s1[-2])]
                err = np.abs(inner[:, None] - expected[None, :]).min(axis=1)
                c2, _, expect = makeup.make_jittered(
                    src, str(d / "reg2.bvh"), str(d / "jit.bvh"), reps=30, jitter=0.15, seed=seed
                )
                bj = beat_frames(d / "jit.bvh")
                e2 = expect(beat_frames(d / "reg2.bvh"))
                inner2 = bj[(bj > c2) & (bj < 29 * c2)]
                err2 = np.abs(inner2[:, None] - e2[None, :]).min(axis=1)
                ok = max(err.max(), err2.max()) <= 1.0 and max(err.mean(), err2.mean()) <= 0.25
                out.append(
                    {
                        "walk": walk,
                        "seed": seed,
                        "cycle_frames": int(c),
                        "beats": int(inner.size),
                        "warp_max": round(float(err.max()), 3),
                        "warp_mean": round(float(err.mean()), 3),
                        "jitter_max": round(float(err2.max()), 3),
                        "jitter_mean": round(float(err2.mean()), 3),
                        "pass": bool(ok and inner.size >= 20),
                    }
                )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3, help="timed runs per salsa clip (median reported)")
    ap.add_argument("--salsa-tempo", default="120:240", help="salsa tempo prior LOW:HIGH bpm")
    ap.add_argument("--walks", default="1,5,12,20", help="Bandai dataset-2 walk numbers for accuracy")
    ap.add_argument("--seeds", default="2,5", help="make-up warp seeds for accuracy")
    ap.add_argument("--no-accuracy", action="store_true", help="skip the make-up accuracy protocol")
    args = ap.parse_args(argv)
    tune_process()
    if not (DATA / "cmu-salsa").is_dir():
        print(json.dumps({"error": f"shared data not found under {DATA}"}))
        return 1
    lo, _, hi = args.salsa_tempo.partition(":")
    rows, speed = salsa((float(lo), float(hi)), args.runs)
    result: dict[str, Any] = {
        "salsa": rows,
        "salsa_agree": sum(r["agree"] for r in rows),
        "salsa_agree_salsa_prior": sum(r["agree_salsa_prior"] for r in rows),
        "salsa_trials": len(rows),
        "speed": speed,
    }
    if not args.no_accuracy and (ACCEPTANCE / "makeup.py").is_file():
        acc = accuracy([int(w) for w in args.walks.split(",")], [int(s) for s in args.seeds.split(",")])
        result["accuracy"] = acc
        result["accuracy_passed"] = f"{sum(a['pass'] for a in acc)}/{len(acc)}"
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
