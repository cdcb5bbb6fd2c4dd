"""Benchmark: what every engine's results are worth, measured on the motion they return.

Runs each engine through the public command line (``segue build`` / ``segue synth``, so any
installed version can be measured: ``--segue PATH``) on real data from ``../shared/data``, on
feasible and infeasible requests, and measures each output BVH here, independently of the
engine: the request's goals (body, joint, obstacle, path, music beats, length) and the physical
plausibility against the database's own example clips, with :func:`motion.quality.assess`. Beside
each measurement it prints what the result's own report said (``said``: its ``ok`` and the
goal errors it claims), so a report that says more than the motion shows stands out.

Prints one JSON object: ``{"cases": [{"engine", "case", "seconds", "measured": {"ok", "reasons",
"goals", "plausibility"}, "said": {"ok", "goals"}, "honest"}], "summary": {...}}``. ``honest`` is
false when the report claims a goal met that the output misses (more than 2 cm / 2 degrees off
what the report says), or claims ``ok`` while the measurement finds a reason it is not.

    python bench/quality.py [--segue PATH] [--only graph,rhythm] [--budget S]
"""

from __future__ import annotations

import argparse
import glob
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from motion import Motion, read_bvh  # noqa: E402
from motion.goals import BeatGoal, BodyGoal, Goal, JointGoal, LengthGoal, ObstacleGoal, PathGoal  # noqa: E402
from motion.plausibility import Reference, reference_from_positions  # noqa: E402
from motion.quality import QualityInputs, assess  # noqa: E402
from motion.regions import FloorRegion  # noqa: E402

DATA = ROOT.parent / "shared" / "data"
BANDAI = DATA / "bandai-namco" / "dataset-2"
SALSA = DATA / "cmu-salsa"


def bandai(kinds: list[tuple[str, int]]) -> list[str]:
    out: list[str] = []
    for kind, k in kinds:
        out += sorted(glob.glob(str(BANDAI / f"dataset-2_{kind}_normal_*.bvh")))[-k:]
    return out


def reference_of(files: list[str]) -> Reference:
    """What the example clips do (metres: the files' units are guessed as the engines do)."""
    examples = []
    for f in files:
        m = read_bvh(f)
        m = m.to_units("m") if m.units != "unknown" else m
        examples.append((m.global_positions() * m.metres_per_unit, m.skeleton, m.fps))
    return reference_from_positions(examples)


def graph_goals(req: dict[str, Any], motion: Motion) -> list[Goal]:
    goals: list[Goal] = [LengthGoal(int(req["frames"]))]
    counts: dict[str, int] = {}
    for c in req.get("constraints", []):
        i = counts.get(c["type"], 0)
        counts[c["type"]] = i + 1
        name = f"{c['type']}[{i}]"
        if c["type"] == "body":
            h = c.get("heading_deg")
            goals.append(
                BodyGoal(name, c["frame"], np.array(c["position"]), None if h is None else np.radians(h))
            )
        elif c["type"] == "joint":
            j = motion.skeleton.index(c["joint"])
            goals.append(JointGoal(name, c["frame"], j, np.array(c["position"])))
        elif c["type"] == "obstacle":
            d = c["disc"]
            goals.append(ObstacleGoal(name, FloorRegion.disc(d["center"], d["radius"])))
    return goals


def cases(budget: float) -> list[dict[str, Any]]:
    """Every case: engine, name, database spec (clip files), request, the example clips (the
    plausibility reference) and how to build the goals from the request and the output."""
    loco = bandai([("walk", 10), ("walk-turn-left", 10), ("walk-turn-right", 10), ("run", 5)])
    graph_db = {"kind": "graph", "clips": [{"bvh": f} for f in loco]}

    def body_req(
        goal: tuple[float, float, float], extra: list[dict[str, Any]] | None = None
    ) -> dict[str, Any]:
        return {
            "engine": "graph",
            "frames": 300,
            "seed": 2,
            "budget_s": budget,
            "constraints": [
                {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
                {"type": "body", "frame": 299, "position": list(goal[:2]), "heading_deg": goal[2]},
                *(extra or []),
            ],
        }

    out: list[dict[str, Any]] = [
        {
            "engine": "graph",
            "case": "reachable goal 5.8 m away",
            "db": graph_db,
            "request": body_req((3.0, 5.0, -90.0)),
            "examples": loco,
            "goals": graph_goals,
        },
        {
            "engine": "graph",
            "case": "unreachable goal 85 m away",
            "db": graph_db,
            "request": body_req((60.0, 60.0, 0.0)),
            "examples": loco,
            "goals": graph_goals,
        },
        {
            "engine": "graph",
            "case": "joint + obstacle (README example)",
            "db": graph_db,
            "request": body_req(
                (4.0, 1.0, 90.0),
                [
                    {"type": "joint", "frame": 150, "joint": "Head", "position": [2.0, 1.35, 0.5]},
                    {"type": "obstacle", "disc": {"center": [3.0, 0.75], "radius": 0.4}},
                ],
            ),
            "examples": loco,
            "goals": graph_goals,
        },
    ]
    ann_files = bandai([("walk", 12), ("run", 12), ("wave-both-hands", 12)])
    ann_clips = []
    for i, f in enumerate(ann_files):
        kind = Path(f).stem.split("_")[1]
        ann_clips.append(
            {"bvh": f, "labels": [{"label": kind, "start": 0, "end": 100000}]} if i % 12 < 3 else {"bvh": f}
        )
    tl = [
        {"label": "walk", "start": 0, "end": 150, "value": 1},
        {"label": "run", "start": 150, "end": 300, "value": 1},
        {"label": "wave-both-hands", "start": 0, "end": 300, "value": -1},
    ]

    def ann_goals(req: dict[str, Any], motion: Motion) -> list[Goal]:
        goals: list[Goal] = [LengthGoal(int(req["frames"]))]
        if req.get("end"):
            e = req["end"]
            goals.append(
                BodyGoal("end", int(req["frames"]) - 1, np.array(e["position"]), np.radians(e["heading_deg"]))
            )
        return goals

    ann_db = {"kind": "annotated", "clips": ann_clips}
    ann_req = {"engine": "annotations", "frames": 300, "seed": 4, "budget_s": budget, "timeline": tl}
    far_end = {"end": {"position": [40.0, 0.0], "heading_deg": 90.0}}
    for name, extra in (("walk then run", {}), ("walk then run, end 40 m away (unreachable)", far_end)):
        out.append(
            {
                "engine": "annotations",
                "case": name,
                "db": ann_db,
                "examples": ann_files,
                "goals": ann_goals,
                "request": {**ann_req, **extra},
            }
        )
    leaders = [str(SALSA / f"60_{t}_scaled.bvh") for t in ("02", "04", "06", "10", "11", "12")]
    rh_db = {"kind": "rhythm", "clips": [{"bvh": f} for f in leaders], "beats_per_movement": 4}

    def beat_goals(req: dict[str, Any], motion: Motion) -> list[Goal]:
        bpm, dur = req["music"]["bpm"], req["music"]["duration_s"]
        beats = np.arange(0.0, dur + 1e-9, 60.0 / bpm)
        return [LengthGoal(int(np.floor(beats[-1] * motion.fps + 1e-9)) + 1), BeatGoal("music", beats)]

    for accent in (None, 0.0):
        req: dict[str, Any] = {"engine": "rhythm", "music": {"bpm": 100, "duration_s": 20}, "seed": 2}
        if accent is not None:
            req["accent"] = accent
        out.append(
            {
                "engine": "rhythm",
                "case": f"20 s at 100 BPM, accent {'default' if accent is None else accent}",
                "db": rh_db,
                "request": req,
                "examples": leaders,
                "goals": beat_goals,
            }
        )
    pairs = [
        (str(SALSA / f"60_{t}_scaled.bvh"), str(SALSA / f"61_{t}_scaled.bvh"))
        for t in ("02", "04", "06", "11", "12")
    ]
    ctl_db = {
        "kind": "control",
        "pairs": [{"control": c, "target": t} for c, t in pairs],
        "segmentation": {"method": "beats", "beats_per_segment": 2},
    }
    out.append(
        {
            "engine": "control",
            "case": "salsa follower for held-out leader 60_10",
            "db": ctl_db,
            "examples": [t for _, t in pairs],
            "goals": lambda req, m: [],
            "request": {
                "engine": "control",
                "control": {"bvh": str(SALSA / "60_10_scaled.bvh")},
                "budget_s": budget,
            },
        }
    )
    walks = bandai([("walk", 12), ("walk-turn-left", 6), ("walk-turn-right", 6)])
    walk_db = {"kind": "control", "pairs": [{"target": f} for f in walks]}
    t = np.arange(0, 8.0, 1 / 30)
    path = np.stack((2.0 * np.sin(t / 8 * np.pi), 1.1 * t), axis=-1)  # a gentle S over 8 s

    def path_goals(req: dict[str, Any], motion: Motion) -> list[Goal]:
        pts = np.asarray(req["control"]["trajectory"]["points"])
        return [LengthGoal(len(pts)), PathGoal("path", np.arange(len(pts)), pts, tolerance_cm=10.0)]

    out.append(
        {
            "engine": "control",
            "case": "walk along a performed S path",
            "db": walk_db,
            "examples": walks,
            "goals": path_goals,
            "request": {
                "engine": "control",
                "budget_s": budget,
                "control": {"trajectory": {"fps": 30, "points": np.round(path, 4).tolist()}},
            },
        }
    )
    return out


def said_of(report: dict[str, Any]) -> dict[str, Any]:
    keep = (
        "position_cm",
        "heading_deg",
        "depth_cm",
        "frames",
        "rms_cm",
        "beat_align_mint",
        "beat_align_bailando",
        "satisfied",
    )
    goals = {
        k: {f: v[f] for f in keep if f in v}
        for k, v in report.get("constraint_errors", {}).items()
        if isinstance(v, dict)
    }
    return {"ok": report.get("ok"), "goals": goals}


def honest(measured: dict[str, Any], said: dict[str, Any]) -> bool:
    for name, m in measured["goals"].items():
        s = said["goals"].get(name)
        if s is None:
            continue
        for field, tol in (("position_cm", 2.0), ("heading_deg", 2.0), ("depth_cm", 2.0)):
            if (
                field in s
                and m.get(field) is not None
                and s[field] is not None
                and abs(s[field] - m[field]) > tol
            ):
                return False
        if s.get("satisfied") is True and m.get("satisfied") is False:
            return False
    return not (said["ok"] is True and not measured["ok"])


def run_case(segue: str, case: dict[str, Any], work: Path) -> dict[str, Any]:
    d = work / case["engine"] / str(abs(hash(case["case"])) % 10**8)
    d.mkdir(parents=True, exist_ok=True)
    (d / "db.json").write_text(json.dumps(case["db"]))
    db = work / case["engine"] / f"db-{abs(hash(json.dumps(case['db'], sort_keys=True))) % 10**8}"
    if not (db / "data.npz").exists():
        subprocess.run(
            [segue, "build", str(d / "db.json"), "--out", str(db), "-q"], check=True, capture_output=True
        )
    (d / "req.json").write_text(json.dumps(case["request"]))
    t0 = time.perf_counter()
    r = subprocess.run(
        [
            segue,
            "synth",
            str(d / "req.json"),
            "--db",
            str(db),
            "--out",
            str(d / "out.bvh"),
            "--report",
            str(d / "rep.json"),
            "-q",
        ],
        capture_output=True,
        text=True,
    )
    seconds = time.perf_counter() - t0
    if r.returncode:
        return {
            "engine": case["engine"],
            "case": case["case"],
            "error": (r.stderr or r.stdout).strip()[-300:],
        }
    motion = read_bvh(d / "out.bvh")
    motion = motion.to_units("m") if motion.units != "unknown" else motion
    ref = reference_of(case["examples"])
    goals = tuple(case["goals"](case["request"], motion))
    q = assess(motion, QualityInputs(goals=goals), ref)
    measured = {
        "ok": q.ok,
        "reasons": q.reasons,
        "goals": q.constraint_errors,
        "plausibility": {
            k: {f: v.get(f) for f in ("value", "unit", "reference", "limit", "ok")}
            for k, v in q.plausibility.items()
        },
    }
    said = said_of(json.loads((d / "rep.json").read_text()))
    return {
        "engine": case["engine"],
        "case": case["case"],
        "seconds": round(seconds, 2),
        "measured": measured,
        "said": said,
        "honest": honest(measured, said),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--segue", default=shutil.which("segue") or "segue", help="the segue command to measure")
    ap.add_argument(
        "--only", default="", help="comma-separated engines (graph, annotations, rhythm, control)"
    )
    ap.add_argument("--budget", type=float, default=5.0, help="budget_s of every request")
    ap.add_argument("--keep", help="keep the outputs in this directory")
    args = ap.parse_args(argv)
    if not DATA.exists():
        print(json.dumps({"error": f"{DATA} not found"}))
        return 1
    only = {e for e in args.only.split(",") if e}
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="segue-quality-"))
    results = [run_case(args.segue, c, work) for c in cases(args.budget) if not only or c["engine"] in only]
    done = [r for r in results if "measured" in r]
    summary = {
        "cases": len(results),
        "ok": sum(r["measured"]["ok"] for r in done),
        "honest": sum(r["honest"] for r in done),
        "errors": len(results) - len(done),
    }
    print(json.dumps({"cases": results, "summary": summary}, indent=1))
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
