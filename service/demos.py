"""``segue demo [ENGINE]``: every engine end to end on the bundled CMU samples, in seconds.

``segue demo`` (no engine) converts the bundled salsa leader to GLB, JSON and NPZ and dances it to
120 BPM with the rhythm engine (the README's first job). ``segue demo ENGINE`` runs one engine the
way a user would with ``segue build`` and ``segue synth``: it writes the database spec and the
request it uses (bundled clips named ``sample:NAME``, so both files work from any folder, with the
CLI and over HTTP), builds the database, synthesizes, and writes into ``DIR/ENGINE/``:

``db.json``, ``request.json``
    the spec and the request, as ``segue build`` / ``segue synth`` take them;
``job.json``
    the request with the database's id, as ``POST /v1/jobs`` takes it (the id is the content
    address the server computes for ``db.json``);
``NAME.bvh``, ``NAME.glb``, ``report.json``
    the result and its report (quality verdict ``ok`` with its ``reasons``);
``db/``
    the database directory.

Each demo's request is one the bundled data can satisfy: its result is ``ok``. Only the
standard library is imported at module level (the CLI imports this module to list the engines).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from schemas import Report

Say = Callable[[str], None]

SERVER = "http://127.0.0.1:8000"


def s_curve(radius_m: float, speed_m_s: float, seconds: float, fps: float = 30.0) -> list[list[float]]:
    """A performed floor path ``[[x, z], ...]`` (metres, one point per frame at ``fps``) starting at
    the origin facing +Z: an arc of ``radius_m`` to the right (towards +X) for the first half, then
    to the left, at ``speed_m_s``; rounded to millimetres."""
    if radius_m <= 0 or speed_m_s <= 0 or seconds <= 0 or fps <= 0:
        raise ValueError("radius, speed, duration and fps must be positive")
    steps = int(round(seconds * fps))
    step = speed_m_s / fps
    x = z = heading = 0.0
    points = [[0.0, 0.0]]
    for i in range(steps):
        heading += (1.0 if i < steps / 2 else -1.0) * step / radius_m
        x += step * math.sin(heading)
        z += step * math.cos(heading)
        points.append([round(x, 3), round(z, 3)])
    return points


@dataclass(frozen=True, slots=True)
class Demo:
    """One engine's demo: a spec and a request on bundled samples, and how to present the result."""

    name: str
    """The CLI's name (``segue demo NAME``)."""
    engine: str
    title: str
    spec: dict[str, Any]
    request: dict[str, Any]
    output: str
    """Base name of the result files (``OUTPUT.bvh``, ``OUTPUT.glb``)."""
    tool: str
    """The browser tool that does the same."""
    extra: dict[str, str] = field(default_factory=dict)
    """Other files to write: file name -> bundled sample converted into it (e.g. the leader)."""


def _pairs(*dances: str) -> list[dict[str, str]]:
    out = [{"control": "sample:salsa-leader", "target": "sample:salsa-follower"}]
    out += [{"control": f"sample:salsa-leader-{d}", "target": f"sample:salsa-follower-{d}"} for d in dances]
    return out


WALKS = ["sample:walk", "sample:walk-05-01", "sample:walk-10-04", "sample:walk-12-02"]


def _labelled(ref: str, label: str, end: int) -> dict[str, Any]:
    """A clip labelled over frames ``[1, end)`` at 30 fps (frame 0 of the CMU-daz clips is a
    reference pose, not part of the action)."""
    return {"bvh": ref, "labels": [{"label": label, "start": 1, "end": end}]}


DEMOS: dict[str, Demo] = {
    d.name: d
    for d in (
        Demo(
            name="control",
            engine="control",
            title="a salsa follower for a leader the database has never seen (control by example)",
            spec={
                "kind": "control",
                "pairs": _pairs("02", "04", "05"),
                "segmentation": {"method": "beats", "beats_per_segment": 2},
            },
            request={"engine": "control", "control": {"bvh": "sample:salsa-leader-12"}},
            output="follower",
            tool="Partner",
            extra={"leader.glb": "salsa-leader-12"},
        ),
        Demo(
            name="walk",
            engine="control",
            title="a walk along a performed S-shaped path, 6 s at 1.2 m/s (control by example)",
            spec={
                "kind": "control",
                "fps": 30,
                "pairs": [{"target": ref} for ref in WALKS],
                "segmentation": {"method": "footplants"},
            },
            request={
                "engine": "control",
                "control": {"trajectory": {"fps": 30, "points": s_curve(5.0, 1.2, 6.0)}},
            },
            output="walk",
            tool="Path",
        ),
        Demo(
            name="graph",
            engine="graph",
            title="8 s from the origin to a goal 8 m ahead and 1 m right, around a post (motion graph)",
            spec={"kind": "graph", "fps": 30, "clips": [{"bvh": ref} for ref in WALKS]},
            request={
                "engine": "graph",
                "frames": 240,
                "seed": 1,
                "alternatives": 3,
                "constraints": [
                    {"type": "body", "frame": 0, "position": [0, 0], "heading_deg": 0},
                    {"type": "body", "frame": 239, "position": [1.0, 8.0], "heading_deg": 10},
                    {"type": "obstacle", "disc": {"center": [0.0, 4.0], "radius": 0.3}},
                ],
            },
            output="graph",
            tool="Constraints",
        ),
        Demo(
            name="annotations",
            engine="annotations",
            title="5 s of walking then 3 s of running, never jumping, from a label timeline (annotations)",
            spec={
                "kind": "annotated",
                "clips": [
                    _labelled("sample:walk", "walk", 80),
                    _labelled("sample:walk-05-01", "walk", 150),
                    _labelled("sample:run-09-01", "run", 38),
                    _labelled("sample:run-09-02", "run", 33),
                    _labelled("sample:jump-13-11", "jump", 104),
                    {"bvh": "sample:walk-10-04"},
                    {"bvh": "sample:walk-12-02"},
                    {"bvh": "sample:run-09-03"},
                    {"bvh": "sample:run-09-04"},
                    {"bvh": "sample:jump-13-32"},
                ],
            },
            request={
                "engine": "annotations",
                "frames": 240,
                "seed": 3,
                "timeline": [
                    {"label": "walk", "start": 0, "end": 150, "value": 1},
                    {"label": "run", "start": 150, "end": 240, "value": 1},
                    {"label": "jump", "start": 0, "end": 240, "value": -1},
                ],
            },
            output="timeline",
            tool="Timeline",
        ),
        Demo(
            name="rhythm",
            engine="rhythm",
            title="a salsa solo to a MIDI song that speeds up from 104 to 116 BPM (rhythmic synthesis)",
            spec={"kind": "rhythm", "clips": [{"bvh": "sample:salsa-leader"}], "beats_per_movement": 4},
            request={"engine": "rhythm", "music": {"midi": "sample:song"}, "seed": 1},
            output="dance",
            tool="Music",
        ),
    )
}
"""The engine demos by name (``segue demo NAME``)."""


@dataclass(frozen=True, slots=True)
class DemoResult:
    """What a demo wrote and measured."""

    name: str
    folder: Path
    ok: bool | None
    reasons: list[str]
    build_s: float
    synth_s: float
    total_s: float


def _write_json(path: Path, data: dict[str, Any]) -> None:
    path.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")


def run_demo(name: str, out_root: Path, say: Say = print) -> DemoResult:
    """Run the demo ``name`` (see :data:`DEMOS`) into ``out_root/name/`` and describe it with ``say``.

    Raises :class:`motion.MotionError` when the synthesis finds nothing (it should not)."""
    from motion import MotionError
    from motion.io import load_motion, save_motion
    from workers.local import EventWriter, build_to_dir, synth_from_dir, write_result

    from .summaries import quality_summary

    demo = DEMOS[name]
    t_start = time.perf_counter()
    folder = out_root / name
    folder.mkdir(parents=True, exist_ok=True)
    _write_json(folder / "db.json", demo.spec)
    _write_json(folder / "request.json", demo.request)
    say(f"segue demo {name}: {demo.title}")
    t0 = time.perf_counter()
    info = build_to_dir(folder / "db.json", folder / "db", EventWriter("build"))
    build_s = time.perf_counter() - t0
    article = "an" if info.kind[:1] in "aeiou" else "a"
    say(
        f"  built {article} {info.kind} database: {len(info.clips)} clips, {info.frames} frames, "
        f"{build_s:.1f} s"
    )
    _write_json(folder / "job.json", {**demo.request, "database": info.id})
    t0 = time.perf_counter()
    writer = EventWriter("synth")
    result = synth_from_dir(folder / "request.json", folder / "db", writer)
    synth_s = time.perf_counter() - t0
    if result is None:
        failed = [e.data["error"]["message"] for e in writer.events if e.type.value == "failed"]
        raise MotionError(f"the {name} demo found no result: {'; '.join(failed) or 'no solution'}")
    motion, report = result
    write_result(motion, report, folder / f"{demo.output}.glb", folder / "report.json")
    write_result(motion, report, folder / f"{demo.output}.bvh", None)
    for file, sample in demo.extra.items():
        save_motion(load_motion(f"sample:{sample}"), folder / file)
    seconds = motion.num_frames / motion.fps
    say(
        f"  synthesized {seconds:.1f} s ({motion.num_frames} frames at {motion.fps:g} fps) "
        f"in {synth_s:.1f} s, score {report.score:.4g}"
    )
    say("  " + quality_summary(report).replace("\n", "\n  "))
    _describe(demo, folder, say)
    return DemoResult(
        name, folder, report.ok, list(report.reasons), build_s, synth_s, time.perf_counter() - t_start
    )


def _describe(demo: Demo, folder: Path, say: Say) -> None:
    """What to open, and the same job with the CLI and over HTTP."""
    files = [f"{demo.output}.glb", f"{demo.output}.bvh", "report.json", *demo.extra]
    say(f"  wrote {folder}/: {', '.join(files)}")
    beside = f" (beside {folder / next(iter(demo.extra))})" if demo.extra else ""
    say(f"  open {folder / (demo.output + '.glb')}{beside} in any glTF viewer (Blender, the three.js editor)")
    say("  the same with the CLI:")
    say(f"    segue build {folder / 'db.json'} --out {folder / 'db'}")
    say(
        f"    segue synth {folder / 'request.json'} --db {folder / 'db'} --out {folder / demo.output}.glb "
        f"--report {folder / 'report.json'}"
    )
    say(f"  over HTTP, with `segue serve` running (in the browser: the {demo.tool} tool at {SERVER}/):")
    say(f"    curl -sS -H 'Content-Type: application/json' -d @{folder / 'db.json'} {SERVER}/v1/databases")
    say(f"    curl -sS -H 'Content-Type: application/json' -d @{folder / 'job.json'} {SERVER}/v1/jobs")
    say(f"    curl -sS '{SERVER}/v1/jobs/JOB/events?wait=30'    # JOB: the id the last command answered")
    say(f"    curl -sS -o {demo.output}.glb '{SERVER}/v1/jobs/JOB/result?format=glb'")


def run_classic(out: Path, synth: bool, say: Say = print) -> None:
    """``segue demo`` without an engine: convert the bundled salsa leader to GLB, JSON and NPZ and
    (``synth``) dance it to 120 BPM with the rhythm engine."""
    from motion.io import load_motion, save_motion
    from motion.samples import sample_path

    from .summaries import inspect_summary

    out.mkdir(parents=True, exist_ok=True)
    path = sample_path("salsa-leader")
    motion = load_motion(path)
    info = inspect_summary(path, motion, None)
    say(
        f"sample sample:salsa-leader: {info['frames']} frames at {info['fps']:g} fps, "
        f"{len(info['joints'])} joints, height {info['height_m']:.2f} m ({info['units']})"
    )
    for name in ("salsa-leader.glb", "salsa-leader.json", "salsa-leader.npz"):
        t0 = time.perf_counter()
        save_motion(motion, out / name)
        size_mb = (out / name).stat().st_size / 1e6
        say(f"  wrote {out / name} ({size_mb:.1f} MB, {time.perf_counter() - t0:.2f} s)")
    if synth:
        _classic_dance(out, say)
    say("open the .glb files in any glTF viewer (Blender, the three.js editor, ...) or run `segue serve`")
    say(f"every engine: segue demo {{{','.join(DEMOS)}}} (or `segue demo all`)")


def _classic_dance(out: Path, say: Say) -> Report:
    """The rhythm engine end to end on the bundled leader: a database, then a dance to 120 BPM."""
    from motion import MotionError
    from workers.local import EventWriter, build_to_dir, synth_from_dir, write_result

    spec = {"kind": "rhythm", "clips": [{"bvh": "sample:salsa-leader"}], "beats_per_movement": 4}
    request = {"engine": "rhythm", "music": {"bpm": 120, "duration_s": 12}, "seed": 1, "budget_s": 30}
    _write_json(out / "dance-db.json", spec)
    _write_json(out / "dance-request.json", request)
    t0 = time.perf_counter()
    db = build_to_dir(out / "dance-db.json", out / "dance-db", EventWriter("build"))
    say(f"  built a rhythm database from the leader ({db.frames} frames) in {time.perf_counter() - t0:.1f} s")
    t0 = time.perf_counter()
    result = synth_from_dir(out / "dance-request.json", out / "dance-db", EventWriter("synth"))
    if result is None:
        raise MotionError("the demo dance failed")
    dance, report = result
    write_result(dance, report, out / "salsa-dance.glb", out / "salsa-dance-report.json")
    write_result(dance, report, out / "salsa-dance.bvh", None)
    beats = report.annotations.get("music_beats_s", [])
    align = report.metrics.get("beat_align_mint", float("nan"))
    say(
        f"  synthesized a {dance.num_frames / dance.fps:.0f} s dance to {len(beats)} beats at 120 BPM in "
        f"{time.perf_counter() - t0:.1f} s (beat alignment {align:.2f}): {out / 'salsa-dance.glb'}, .bvh"
    )
    return report
