"""Quality of the control-by-example engine driven by a path: walks generated from held-out hip paths.

Usage: ``python bench/control_walk.py [--set bandai|cmu-daz] [--fps 30]`` from the project root
(needs ../shared/data).

The issue's walk protocol (Hsu et al. 2004, Sec. 6, the walk from a path): a ``control`` database
of walks without control clips (the control is derived from each target's hips; footplant
segmentation); each held-out walk's hips, projected on the floor and sampled at ``--fps`` (a mouse
path), are sent as a ``trajectory`` request, and the generated walk is compared with the path.

* ``bandai``: Bandai-Namco dataset-2, clips 001-010 of walk, walk-turn-left and walk-turn-right in
  the database (30 clips), clips 011-012 of each held out (6 paths);
* ``cmu-daz``: the 30 CMU walks of ``cmu-daz/walks`` sorted by name, the even-numbered ones in the
  database (15 clips), the first 6 odd-numbered ones held out.

Prints one JSON object: per held-out clip and in summary

* ``path_rms_pct_height``: RMS floor distance between the generated walk's hips and the path, in
  percent of the held-out walker's standing height (goal <= 5);
* ``foot_slip_m_s``: mean horizontal speed of the feet while planted, with the contacts the engine
  reports for its output (those its foot clean-up pins; goal <= 0.04), and ``foot_slip_detected_m_s``
  with contacts detected on the output by :func:`motion.contacts.detect_contacts`;
* ``speed_in_m_s`` / ``speed_out_m_s``: mean speed along the path and of the generated hips;
  ``speed_correlation``: correlation of the two speed profiles smoothed over 1 s and
  ``speed_rms_error_m_s`` their RMS difference (speed profile followed; the correlation means
  little on a short walk at a nearly constant speed);
* ``synth_s``: seconds of the whole request (the best solution within the default budget).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter1d

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engines.base import CollectingEmitter, Run  # noqa: E402
from engines.control.engine import ControlEngine  # noqa: E402
from engines.library import ClipInput, build_library, library_to_arrays  # noqa: E402
from engines.registry import parse_database_spec, parse_job_request  # noqa: E402
from motion import Motion  # noqa: E402
from motion.allocator import tune_process  # noqa: E402
from motion.bvh import parse_bvh  # noqa: E402
from motion.ground import ground_frames  # noqa: E402
from motion.metrics import foot_slip  # noqa: E402
from motion.resample import resample  # noqa: E402
from motion.units import standing_height  # noqa: E402

DATA = ROOT.parent / "shared" / "data"


def split(name: str) -> tuple[list[Path], list[Path]]:
    """The database clips and the held-out clips of a set."""
    if name == "bandai":
        b = DATA / "bandai-namco" / "dataset-2"
        kinds = ("walk", "walk-turn-left", "walk-turn-right")
        train = [b / f"dataset-2_{k}_normal_{i:03d}.bvh" for k in kinds for i in range(1, 11)]
        held = [b / f"dataset-2_{k}_normal_{i:03d}.bvh" for k in kinds for i in (11, 12)]
        return train, held
    walks = sorted((DATA / "cmu-daz" / "walks").glob("*.bvh"))
    return walks[0::2], walks[1::2][:6]


def engine_for(train: list[Path]) -> ControlEngine:
    """A walk database (derived controls, footplant segmentation) of ``train``."""
    spec = parse_database_spec(
        {
            "kind": "control",
            "pairs": [{"target": str(p)} for p in train],
            "segmentation": {"method": "footplants"},
        }
    )
    clips = [ClipInput(c.display_name(), Path(str(c.bvh)).read_bytes(), c.units) for c in spec.clips]
    library = build_library(clips, spec.fps)
    arrays = ControlEngine.build(spec, library, CollectingEmitter(), lambda: False)
    arrays.update(library_to_arrays(library))
    return ControlEngine(library, arrays)


def speed(path: np.ndarray, fps: float) -> np.ndarray:
    """``(F,)`` m/s along a floor path ``(F, 2)`` (forward differences, the last repeated)."""
    v = np.linalg.norm(np.diff(path, axis=0), axis=-1) * fps
    return np.concatenate((v, v[-1:]))


def held_walk(engine: ControlEngine, path_file: Path, fps: float) -> dict[str, Any]:
    """Generate a walk along ``path_file``'s hip path sampled at ``fps`` and measure it."""
    held: Motion = parse_bvh(path_file.read_bytes()).to_units("m")
    height = standing_height(held.global_positions())
    sampled = resample(held, fps)
    path, _ = ground_frames(sampled)
    request = parse_job_request(
        {"engine": "control", "control": {"trajectory": {"fps": fps, "points": path.tolist()}}}
    )
    out = CollectingEmitter()
    t0 = time.perf_counter()
    engine.search(request, Run(request.budget_s, emit=out))
    synth_s = time.perf_counter() - t0
    sol = min(out.solutions, key=lambda s: s.score)
    motion = sol.motion
    got, _ = ground_frames(motion)
    n = min(len(got), len(path))
    rms = float(np.sqrt(((got[:n] - path[:n]) ** 2).sum(-1).mean()))
    contacts = sol.annotations["foot_contacts"]
    joints = np.array([motion.skeleton.names.index(j) for j in contacts["joints"]], dtype=np.intp)
    flags = np.array(contacts["flags"], dtype=bool).T  # (F, K)
    v_in, v_out = speed(path[:n], fps), speed(got[:n], motion.fps)
    window = max(1, int(round(fps)))
    smooth_in, smooth_out = uniform_filter1d(v_in, window), uniform_filter1d(v_out, window)
    corr = float(np.corrcoef(smooth_in, smooth_out)[0, 1])
    speed_rms = float(np.sqrt(((smooth_in - smooth_out) ** 2).mean()))
    return {
        "frames": int(motion.num_frames),
        "path_rms_pct_height": round(100 * rms / height, 2),
        "foot_slip_m_s": round(foot_slip(motion, joints=joints, contacts=flags), 4),
        "foot_slip_detected_m_s": round(foot_slip(motion), 4),
        "speed_in_m_s": round(float(v_in.mean()), 3),
        "speed_out_m_s": round(float(v_out.mean()), 3),
        "speed_correlation": round(corr, 3),
        "speed_rms_error_m_s": round(speed_rms, 3),
        "synth_s": round(synth_s, 2),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--set", default="bandai", choices=["bandai", "cmu-daz"], help="which walks")
    ap.add_argument("--fps", type=float, default=30.0, help="rate the held-out paths are sampled at")
    args = ap.parse_args(argv)
    if args.fps <= 0:
        ap.error("--fps must be positive")
    tune_process()
    train, held = split(args.set)
    missing = [str(p) for p in train + held if not p.exists()]
    if missing:
        print(json.dumps({"error": f"missing data: {missing[:3]}"}))
        return 1
    t0 = time.perf_counter()
    engine = engine_for(train)
    build_s = time.perf_counter() - t0
    clips = {p.stem: held_walk(engine, p, args.fps) for p in held}
    keys = ("path_rms_pct_height", "foot_slip_m_s", "foot_slip_detected_m_s", "speed_rms_error_m_s")
    print(
        json.dumps(
            {
                "set": args.set,
                "database_clips": len(train),
                "build_s": round(build_s, 1),
                "held_out": clips,
                "max": {k: max(c[k] for c in clips.values()) for k in keys},
                "min_speed_correlation": min(c["speed_correlation"] for c in clips.values()),
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
