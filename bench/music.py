"""Benchmark: music from recordings (engines/rhythm/audio.py) and dances to them.

Prints one JSON object:

* ``tracking``: beat-tracking F-measure (+-70 ms, beats after the first second) and tempo found on
  generated drum tracks with known beats (tests/engines/audio_synthetic.py): steady, drifting
  tempo, swing, noise, fast and slow;
* ``speed``: decoding + beat tracking time per minute of audio (WAV and MP3), after a warm-up
  call, and the first call's time in a fresh process (numba compiling librosa's kernels);
* ``dance``: a rhythm database from the cmu-salsa leaders (``../shared/data``; else the synthetic
  dancer), a 24 s drifting recording as the music, and the dance's beat-align scores (mint,
  Bailando) against the recording's true beats and in its quality report, with the default
  accent and with ``accent: 0``;
* ``install``: the size on disk of the packages the recordings need (librosa, soundfile, numba,
  llvmlite, audioread, soxr, mido and librosa's other new dependencies).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engines.base import CollectingEmitter, Run  # noqa: E402
from engines.library import ClipInput, build_library, library_to_arrays  # noqa: E402
from engines.rhythm.audio import audio_beats  # noqa: E402
from engines.rhythm.engine import RhythmEngine  # noqa: E402
from motion.metrics import beat_align_scores  # noqa: E402
from schemas.rhythm import RhythmDatabaseSpec, RhythmRequest  # noqa: E402
from tests.engines.audio_synthetic import drifting_beats, drum_track, encode, f_measure  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "cmu-salsa"
CASES: list[dict[str, Any]] = [
    {"name": "steady 120", "bpm": (120, 120)},
    {"name": "drift 96-116", "bpm": (96, 116)},
    {"name": "drift 128-100", "bpm": (128, 100)},
    {"name": "swing 0.15", "bpm": (104, 104), "swing": 0.15},
    {"name": "noise 10 dB", "bpm": (110, 110), "snr_db": 10.0},
    {"name": "drift + swing + noise", "bpm": (92, 112), "swing": 0.1, "snr_db": 12.0},
    {"name": "fast 140-150", "bpm": (140, 150)},
    {"name": "slow 84-90", "bpm": (84, 90)},
]
PACKAGES = (
    "librosa", "soundfile", "numba", "llvmlite", "audioread", "soxr", "mido",
    "lazy_loader", "pooch", "msgpack", "decorator", "cffi", "pycparser",
)  # fmt: skip
"""The packages librosa, soundfile and mido add to the project's environment (pip show Required-by)."""


def _tracking(seconds: float, seeds: list[int]) -> list[dict[str, Any]]:
    rows = []
    for case in CASES:
        fs, tempos = [], []
        for seed in seeds:
            beats = drifting_beats(*case["bpm"], seconds)
            y = drum_track(beats, seconds, case.get("swing", 0.0), case.get("snr_db", 30.0), seed)
            found = audio_beats(encode(y))
            fs.append(f_measure(found.beats_s[found.beats_s > 1.0], beats[beats > 1.0]))
            tempos.append(found.tempo_bpm)
        rows.append(
            {
                "case": case["name"],
                "f_measure_mean": round(float(np.mean(fs)), 3),
                "f_measure_min": round(float(np.min(fs)), 3),
                "tempo_found_bpm": round(float(np.median(tempos)), 1),
            }
        )
    return rows


def _speed() -> dict[str, Any]:
    beats = drifting_beats(100, 120, 60.0)
    y = drum_track(beats, 60.0, seed=1)
    out: dict[str, Any] = {}
    code = (
        f"import sys, time; sys.path.insert(0, {str(ROOT)!r}); from tests.engines.audio_synthetic import *; "
        "from engines.rhythm.audio import audio_beats; b = drifting_beats(110, 110, 10.0); "
        "d = encode(drum_track(b, 10.0)); t = time.perf_counter(); audio_beats(d); "
        "print(time.perf_counter() - t)"
    )
    first = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    out["first_call_fresh_process_s"] = round(float(first.stdout.strip().splitlines()[-1]), 2)
    for fmt in ("WAV", "MP3"):
        data = encode(y, fmt)
        audio_beats(data)
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            audio_beats(data)
            best = min(best, time.perf_counter() - t0)
        out[f"{fmt.lower()}_s_per_minute"] = round(float(best), 3)
    return out


def _engine() -> tuple[RhythmEngine, str]:
    clips = ["02", "04", "06", "10", "11", "12"]
    files = [DATA / f"60_{c}_scaled.bvh" for c in clips]
    if all(f.exists() for f in files):
        lib = build_library([ClipInput(f.stem, f.read_bytes()) for f in files])
        fields: dict[str, Any] = {"clips": [{"bvh": f.name} for f in files]}
        source = "cmu-salsa leaders " + ",".join(clips)
    else:
        from tests.engines.rhythm_synthetic import library

        lib, beats = library(count=4, fps=120.0, seconds=30.0)
        fields = {"clips": [{"bvh": f"{n}.bvh"} for n in lib.names], "clip_beats": beats}
        source = "synthetic"
    spec = RhythmDatabaseSpec.model_validate({"kind": "rhythm", "beats_per_movement": 4, **fields})
    arrays = library_to_arrays(lib)
    arrays.update(RhythmEngine.build(spec, lib, CollectingEmitter(), lambda: False))
    return RhythmEngine(lib, arrays), source


def _dance(seeds: list[int]) -> dict[str, Any]:
    engine, source = _engine()
    out: dict[str, Any] = {"source": source, "music": "drift 96-116 BPM, 24 s, WAV", "seeds": seeds}
    beats = drifting_beats(96, 116, 24.0)
    song = encode(drum_track(beats, 24.0, seed=3))
    for tag, accent in (("default_accent", None), ("accent_0", 0.0)):
        true_m, true_b, rep_m, rep_b = [], [], [], []
        for seed in seeds:
            body: dict[str, Any] = {"music": {"audio": "song.wav"}, "seed": seed}
            if accent is not None:
                body["accent"] = accent
            req = RhythmRequest.model_validate(body)
            req.attach_inputs({"song.wav": song})
            keep = CollectingEmitter()
            engine.search(req, Run(30.0, emit=keep))
            sol = keep.latest
            assert sol is not None and sol.quality is not None
            mint, bail, _ = beat_align_scores(sol.motion.global_positions(), sol.motion.fps, beats)
            true_m.append(mint)
            true_b.append(bail)
            rep_m.append(sol.quality.metrics["beat_align_mint"])
            rep_b.append(sol.quality.metrics["beat_align_bailando"])
        out[tag] = {
            "true_beats_mint": round(float(np.mean(true_m)), 3),
            "true_beats_bailando": round(float(np.mean(true_b)), 3),
            "worst_seed_min_of_both": round(float(min(min(true_m), min(true_b))), 3),
            "report_mint": round(float(np.mean(rep_m)), 3),
            "report_bailando": round(float(np.mean(rep_b)), 3),
        }
    return out


def _install() -> dict[str, Any]:
    import importlib.metadata as md

    sizes: dict[str, float] = {}
    for name in PACKAGES:
        try:
            dist = md.distribution(name)
        except md.PackageNotFoundError:
            continue
        total = 0
        for f in dist.files or []:
            p = Path(str(dist.locate_file(f)))
            if p.is_file():
                total += p.stat().st_size
        sizes[name] = round(total / 1e6, 1)
    return {"mb_by_package": sizes, "total_mb": round(sum(sizes.values()), 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=24.0, help="length of each tracking test track")
    ap.add_argument("--seeds", default="0,1,2", help="noise seeds of the tracking tracks")
    ap.add_argument("--dance-seeds", default="1,2,3", help="synthesis seeds of the dances")
    ap.add_argument("--skip-dance", action="store_true", help="tracking, speed and install size only")
    args = ap.parse_args()
    out: dict[str, Any] = {"speed": _speed()}
    out["tracking"] = _tracking(args.seconds, [int(s) for s in args.seeds.split(",")])
    if not args.skip_dance:
        out["dance"] = _dance([int(s) for s in args.dance_seeds.split(",")])
    out["install"] = _install()
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
