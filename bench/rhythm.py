"""Benchmark: the rhythm engine on cmu-salsa (needs ../shared/data; else a synthetic dancer).

Builds a rhythm database from the salsa leader dances (``--clips``, 4 beats per movement), then
measures, and prints as one JSON object:

* ``build_s``, ``movements``, ``groups``;
* ``one_character``: synthesis throughput of one dancer (graph walk, blending, time warp, joins)
  at the database rate for ``--seconds`` of music, in output frames per second, and the same
  with foot cleanup, beat analysis of the output and report (``search_frames_per_s``, the whole
  ``search``);
* ``crowd``: the largest number of dancers whose synthesis at 30 fps keeps up with real time in
  this process (one core: numpy runs single-threaded here), free dancing and with crowd steering
  (each character avoiding the others); a second core doubles it by splitting the crowd;
* the beat-align scores (AIST++/mint, Bailando) of the one-character dance with the default beat
  accent and with ``accent: 0`` (the paper's linear warp), whether its quality report is ``ok``,
  its body speed's 99th percentile over the examples', and its foot slip.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engines.base import CollectingEmitter, Run, Solution  # noqa: E402
from engines.library import ClipInput, MotionLibrary, build_library, library_to_arrays  # noqa: E402
from engines.rhythm.engine import RhythmEngine, music_beats  # noqa: E402
from engines.rhythm.music import bpm_beats  # noqa: E402
from engines.rhythm.synth import initial_dancers, synthesize  # noqa: E402
from motion.metrics import foot_slip  # noqa: E402
from schemas.rhythm import RhythmDatabaseSpec, RhythmRequest  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "cmu-salsa"


def _library(clips: list[str]) -> tuple[MotionLibrary, dict[str, Any], str]:
    files = [DATA / f"60_{c}_scaled.bvh" for c in clips]
    if all(f.exists() for f in files):
        lib = build_library([ClipInput(f.stem, f.read_bytes()) for f in files])
        return lib, {"clips": [{"bvh": f.name} for f in files]}, "cmu-salsa leaders " + ",".join(clips)
    from tests.engines.rhythm_synthetic import library

    lib, beats = library(count=4, fps=120.0, seconds=30.0)
    return lib, {"clips": [{"bvh": f"{n}.bvh"} for n in lib.names], "clip_beats": beats}, "synthetic"


def _quality(sol: Solution, tag: str) -> dict[str, Any]:
    """Beat alignment (both conventions), ``ok`` and the body's speed against the examples, from
    the dance's quality report."""
    q = sol.quality
    assert q is not None
    return {
        f"beat_align_mint_{tag}": round(q.metrics["beat_align_mint"], 3),
        f"beat_align_bailando_{tag}": round(q.metrics["beat_align_bailando"], 3),
        f"ok_{tag}": q.ok,
        f"root_speed_p99_ratio_{tag}": round(
            q.plausibility["root_speed_p99"]["value"] / q.plausibility["root_speed_p99"]["reference"], 3
        ),
        f"reasons_{tag}": q.reasons,
    }


def _sweep(engine: RhythmEngine, bpms: list[float]) -> list[dict[str, Any]]:
    """The 20 s dance at each tempo, seeds 1-3, default accent and none: beat alignment in both
    conventions (mean over seeds), how many results are ``ok`` and why the others are not."""
    out = []
    for bpm in bpms:
        row: dict[str, Any] = {"bpm": bpm}
        for tag, accent in (("default_accent", None), ("accent_0", 0.0)):
            mint, bail, ok, why = [], [], 0, []
            for seed in (1, 2, 3):
                body: dict[str, Any] = {"music": {"bpm": bpm, "duration_s": 20}, "seed": seed}
                if accent is not None:
                    body["accent"] = accent
                keep = CollectingEmitter()
                engine.search(RhythmRequest.model_validate(body), Run(10.0, emit=keep))
                assert keep.latest is not None and keep.latest.quality is not None
                q = keep.latest.quality
                mint.append(q.metrics["beat_align_mint"])
                bail.append(q.metrics["beat_align_bailando"])
                ok += int(q.ok)
                why += [f"seed {seed}: {r}" for r in q.reasons]
            row[tag] = {
                "mint": round(float(np.mean(mint)), 3),
                "bailando": round(float(np.mean(bail)), 3),
                "ok": f"{ok}/3",
                "reasons": why,
            }
        out.append(row)
    return out


def _crowd_rate(engine: RhythmEngine, count: int, seconds: float, avoid: bool) -> float:
    """Seconds of music synthesized per second of compute for ``count`` dancers at 30 fps."""
    t = engine.tables
    beats = bpm_beats(110, seconds)
    dancers = initial_dancers(count, "grid", 1.5, np.zeros(2), 0.0)
    req = RhythmRequest.model_validate(
        {"music": {"bpm": 110, "duration_s": seconds}, "characters": count, "avoid": avoid}
    )
    control = engine.make_control(req, beats, dancers)
    t0 = time.perf_counter()
    synthesize(t, beats, 30.0, dancers, np.random.default_rng(0), control, accent=0.6)
    return seconds / (time.perf_counter() - t0)


def _largest_crowd(engine: RhythmEngine, seconds: float, avoid: bool) -> tuple[int, list[dict[str, float]]]:
    trials: list[dict[str, float]] = []
    lo, hi = 0, 0
    n = 250
    while True:  # doubling until it falls behind real time
        rate = _crowd_rate(engine, n, seconds, avoid)
        trials.append({"characters": n, "realtime_factor": round(rate, 3)})
        if rate < 1.0:
            hi = n
            break
        lo = n
        n *= 2
        if n > 64_000:
            return lo, trials
    for _ in range(4):  # bisection
        mid = (lo + hi) // 2
        rate = _crowd_rate(engine, mid, seconds, avoid)
        trials.append({"characters": mid, "realtime_factor": round(rate, 3)})
        lo, hi = (mid, hi) if rate >= 1.0 else (lo, mid)
    return lo, trials


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--clips", default="02,04,06,10,11,12", help="salsa trial numbers (60_XX)")
    ap.add_argument("--seconds", type=float, default=60.0, help="music length for one character")
    ap.add_argument("--crowd-seconds", type=float, default=4.0, help="music length per crowd trial")
    ap.add_argument("--bpm", type=float, default=110.0)
    ap.add_argument(
        "--sweep",
        default="",
        help="comma-separated BPMs: only the 20 s dance at each (seeds 1-3), with and without the accent",
    )
    args = ap.parse_args()
    lib, spec_fields, source = _library(args.clips.split(","))
    spec = RhythmDatabaseSpec.model_validate({"kind": "rhythm", "beats_per_movement": 4, **spec_fields})
    t0 = time.perf_counter()
    arrays = library_to_arrays(lib)
    arrays.update(RhythmEngine.build(spec, lib, CollectingEmitter(), lambda: False))
    build_s = time.perf_counter() - t0
    engine = RhythmEngine(lib, arrays)
    t = engine.tables

    beats = bpm_beats(args.bpm, args.seconds)
    synthesize(
        t, beats[:9], t.fps, initial_dancers(1, "grid", 1.0, np.zeros(2), 0.0), np.random.default_rng(0)
    )
    best = np.inf
    for rep in range(3):
        d = initial_dancers(1, "grid", 1.0, np.zeros(2), 0.0)
        t1 = time.perf_counter()
        r = synthesize(t, beats, t.fps, d, np.random.default_rng(rep), None, accent=0.6)
        best = min(best, time.perf_counter() - t1)
    frames = r.root.shape[1]

    req = RhythmRequest.model_validate({"music": {"bpm": args.bpm, "duration_s": 20}, "seed": 2})
    keep = CollectingEmitter()
    t2 = time.perf_counter()
    engine.search(req, Run(10.0, emit=keep))
    search_s = time.perf_counter() - t2
    assert keep.latest is not None
    sol = keep.latest
    plain = CollectingEmitter()
    engine.search(req.model_copy(update={"accent": 0.0}), Run(10.0, emit=plain))
    assert plain.latest is not None

    if args.sweep:
        print(
            json.dumps(
                {"source": source, "sweep": _sweep(engine, [float(b) for b in args.sweep.split(",")])},
                indent=1,
            )
        )
        return
    free_n, free_trials = _largest_crowd(engine, args.crowd_seconds, avoid=False)
    steer_n, steer_trials = _largest_crowd(engine, args.crowd_seconds, avoid=True)
    out = {
        "source": source,
        "frames_db": lib.total_frames,
        "fps_db": t.fps,
        "build_s": round(build_s, 2),
        "movements": int(t.root.shape[0]),
        "groups": int(t.p.shape[0]),
        "one_character": {
            "music_s": args.seconds,
            "frames": frames,
            "synth_frames_per_s": round(frames / best),
            "search_frames_per_s": round(sol.motion.num_frames / search_s),
            "search_s_for_20s": round(search_s, 3),
        },
        "dance_20s": {
            "bpm": args.bpm,
            **_quality(sol, "default_accent"),
            **_quality(plain.latest, "accent_0"),
            "foot_slip_m_s": round(foot_slip(sol.motion), 4),
            "music_beats": len(music_beats(req)),
            "motion_beats_detected": len(sol.annotations["motion_beats_s"]),
        },
        "crowd_30fps_one_process": {
            "largest_realtime_free": free_n,
            "largest_realtime_steering": steer_n,
            "trials_free": free_trials,
            "trials_steering": steer_trials,
        },
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
