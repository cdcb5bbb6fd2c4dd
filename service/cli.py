"""The ``segue`` command line.

Commands::

    segue inspect FILE [--json] [--units U]       frames, fps, joints, height and units guess
    segue beats FILE [--json] [--joints A,B] [--positions] [--tempo LO:HI]   motion beats (Kim et al. 2003)
    segue convert IN OUT [--fps N] [--target T]   BVH -> .bvh/.bvh.gz/.glb/.json/.npz
    segue samples                                 list the bundled sample clips
    segue demo [--out DIR]                        inspect + convert a bundled sample
    segue build SPEC.json --out DIR               build a database (same JSON as POST /v1/databases)
    segue synth REQUEST.json --db DIR --out OUT   run a job in-process (same JSON as POST /v1/jobs)
    segue serve [--host H] [--port P] [--redis URL]   the HTTP/WebSocket API (+ embedded workers)
    segue worker --redis URL                      a Redis job worker

``FILE``/``IN`` may be ``sample:NAME`` for a bundled sample (see ``segue samples``). Bad input
exits with status 2 and a one-line message naming the problem.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from engines.base import EngineError
from engines.registry import UnavailableError, load_plugins
from motion import Motion, MotionError
from motion.allocator import tune_process
from motion.beats import detect_beats
from motion.bvh import BvhLimits, detect_units
from motion.export.targets import TARGETS
from motion.ground import add_ground_root
from motion.io import OUTPUT_SUFFIXES, load_motion, save_motion
from motion.resample import resample
from motion.samples import SAMPLES, sample_path
from motion.units import METRES_PER_UNIT
from schemas import EventType, JobEvent, Report
from schemas.jobs import RequestError
from workers.execute import JobFailure
from workers.settings import get_settings, with_options

SAMPLE_PREFIX = "sample:"


def _resolve(path: str) -> Path:
    if path.startswith(SAMPLE_PREFIX):
        return sample_path(path[len(SAMPLE_PREFIX) :])
    return Path(path)


def _limits(args: argparse.Namespace) -> BvhLimits:
    return BvhLimits(max_joints=args.max_joints, max_frames=args.max_frames)


def inspect_summary(path: Path, motion: Motion, declared: str | None) -> dict[str, Any]:
    """The facts ``segue inspect`` reports, JSON-ready."""
    guess = detect_units(motion)
    mpu = motion.metres_per_unit
    return {
        "file": str(path),
        "name": motion.name,
        "frames": motion.num_frames,
        "fps": motion.fps,
        "duration_s": round(motion.duration_s, 6),
        "joints": list(motion.skeleton.names),
        "parents": [int(p) for p in motion.skeleton.parents],
        "channels": motion.skeleton.num_channels,
        "end_sites": int(motion.skeleton.end_site_parents.size),
        "units": motion.units,
        "units_source": "declared" if declared else "guess",
        "height": round(guess.height, 6),
        "height_m": round(guess.height * mpu, 4),
        "units_guess": {
            "units": guess.units,
            "height_m": round(guess.height_m, 4),
            "plausible": guess.plausible,
        },
    }


def cmd_inspect(args: argparse.Namespace) -> int:
    path = _resolve(args.file)
    motion = load_motion(path, units=args.units, limits=_limits(args))
    info = inspect_summary(path, motion, args.units)
    if args.json:
        print(json.dumps(info))
        return 0
    joints = info["joints"]
    shown = ", ".join(joints[:12]) + (f", ... (+{len(joints) - 12})" if len(joints) > 12 else "")
    guess = info["units_guess"]
    print(f"{path}")
    print(f"  frames     {info['frames']} at {info['fps']:g} fps ({info['duration_s']:.2f} s)")
    print(f"  joints     {len(joints)}: {shown}")
    print(f"  channels   {info['channels']}, end sites {info['end_sites']}")
    print(f"  height     {info['height']:.4g} file units = {info['height_m']:.2f} m in {info['units']}")
    note = "" if guess["plausible"] else " (implausible: declare --units)"
    src = "declared" if args.units else f"guessed from height{note}"
    print(f"  units      {info['units']} ({src})")
    return 0


def _tempo_range(text: str) -> tuple[float, float]:
    lo, sep, hi = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return float(lo), float(hi)
    except ValueError:
        raise MotionError(f"--tempo {text!r}: expected LOW:HIGH beats per minute, e.g. 40:200") from None


def cmd_beats(args: argparse.Namespace) -> int:
    path = _resolve(args.file)
    motion = load_motion(path, limits=_limits(args))
    joints: list[str | int] | None = None
    if args.joints:
        joints = [int(j) if j.strip().isdigit() else j.strip() for j in args.joints.split(",") if j.strip()]
    beats = detect_beats(
        motion, joints=joints, use_positions=args.positions, tempo_bpm=_tempo_range(args.tempo)
    )
    info = {
        "file": str(path),
        "fps": motion.fps,
        "period_s": round(beats.period_s, 6),
        "bpm": round(beats.bpm, 4),
        "phase_s": round(beats.phase_s, 6),
        "beats_s": [round(float(t), 6) for t in beats.times_s],
        "candidates": int(beats.candidates_s.size),
    }
    if args.json:
        print(json.dumps(info))
        return 0
    frames = beats.frames(motion.fps)
    print(f"{path}")
    period_frames = beats.period_s * motion.fps
    print(f"  tempo      {info['bpm']:.1f} bpm (period {beats.period_s:.3f} s = {period_frames:.2f} frames)")
    print(f"  beats      {len(frames)} from {info['candidates']} candidates")
    shown = ", ".join(f"{t:.3f}" for t in beats.times_s[:16])
    print(f"  times (s)  {shown}{', ...' if len(frames) > 16 else ''}")
    return 0


def cmd_convert(args: argparse.Namespace) -> int:
    src = _resolve(args.input)
    motion = load_motion(src, units=args.in_units, limits=_limits(args))
    if args.frames:
        start, _, stop = args.frames.partition(":")
        try:
            motion = motion.slice(int(start or 0), int(stop) if stop else None)
        except ValueError:
            raise MotionError(f"--frames {args.frames!r}: expected START:STOP frame numbers") from None
    if args.fps is not None:
        motion = resample(motion, args.fps)
    if args.ground_root and not args.output.lower().endswith(".glb"):
        motion = add_ground_root(motion)
    t0 = time.perf_counter()
    notes = save_motion(motion, args.output, target=args.target, units=args.units)
    for note in notes:
        print(f"segue: note: {note}", file=sys.stderr)
    if not args.quiet:
        print(
            f"wrote {args.output}: {motion.num_frames} frames at {motion.fps:g} fps, "
            f"{motion.num_joints} joints, target {args.target} ({time.perf_counter() - t0:.2f} s)"
        )
    return 0


def cmd_samples(args: argparse.Namespace) -> int:
    for name in SAMPLES:
        print(f"{SAMPLE_PREFIX}{name}\t{sample_path(name)}")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = sample_path("salsa-leader")
    motion = load_motion(path)
    info = inspect_summary(path, motion, None)
    print(
        f"sample {SAMPLE_PREFIX}salsa-leader: {info['frames']} frames at {info['fps']:g} fps, "
        f"{len(info['joints'])} joints, height {info['height_m']:.2f} m ({info['units']})"
    )
    for name in ("salsa-leader.glb", "salsa-leader.json", "salsa-leader.npz"):
        t0 = time.perf_counter()
        save_motion(motion, out / name)
        size_mb = (out / name).stat().st_size / 1e6
        print(f"  wrote {out / name} ({size_mb:.1f} MB, {time.perf_counter() - t0:.2f} s)")
    if not args.no_synth:
        _demo_dance(out)
    print("open the .glb files in any glTF viewer (Blender, the three.js editor, ...) or run `segue serve`")
    return 0


def _demo_dance(out: Path) -> None:
    """The rhythm engine end to end on the bundled leader: a database, then a dance to 120 BPM."""
    from workers.local import EventWriter, build_to_dir, synth_from_dir, write_result

    spec = {"kind": "rhythm", "clips": [{"bvh": str(sample_path("salsa-leader"))}], "beats_per_movement": 4}
    request = {"engine": "rhythm", "music": {"bpm": 120, "duration_s": 12}, "seed": 1, "budget_s": 30}
    (out / "dance-db.json").write_text(json.dumps(spec, indent=2), encoding="utf-8")
    (out / "dance-request.json").write_text(json.dumps(request, indent=2), encoding="utf-8")
    t0 = time.perf_counter()
    db = build_to_dir(out / "dance-db.json", out / "dance-db", EventWriter("build"))
    print(
        f"  built a rhythm database from the leader ({db.frames} frames) in {time.perf_counter() - t0:.1f} s"
    )
    t0 = time.perf_counter()
    result = synth_from_dir(out / "dance-request.json", out / "dance-db", EventWriter("synth"))
    if result is None:
        raise MotionError("the demo dance failed")
    dance, report = result
    write_result(dance, report, out / "salsa-dance.glb", out / "salsa-dance-report.json")
    write_result(dance, report, out / "salsa-dance.bvh", None)
    beats = report.annotations.get("music_beats_s", [])
    align = report.metrics.get("beat_align_mint", float("nan"))
    print(
        f"  synthesized a {dance.num_frames / dance.fps:.0f} s dance to {len(beats)} beats at 120 BPM in "
        f"{time.perf_counter() - t0:.1f} s (beat alignment {align:.2f}): {out / 'salsa-dance.glb'}, .bvh"
    )


def _validation_message(exc: ValidationError) -> str:
    parts = []
    for err in exc.errors()[:5]:
        where = ".".join(str(p) for p in err["loc"]) or "(top level)"
        parts.append(f"{where}: {err['msg']}")
    more = f" (+{len(exc.errors()) - 5} more)" if len(exc.errors()) > 5 else ""
    return "; ".join(parts) + more


def _echo(event: JobEvent) -> None:
    if event.type == EventType.progress:
        print(
            f"  {100 * event.data.get('fraction', 0):5.1f}%  {event.data.get('message', '')}", file=sys.stderr
        )
    elif event.type in (EventType.solution, EventType.alternative):
        verdict = "" if event.data.get("ok") is None else (" ok" if event.data["ok"] else " NOT ok")
        print(
            f"  {event.type.value} {event.data['result']}: score {event.data['score']:.6g} "
            f"after {event.data['elapsed_ms']:.0f} ms,{verdict}",
            file=sys.stderr,
        )
    elif event.type == EventType.failed:
        print(f"  failed: {event.data['error']['message']}", file=sys.stderr)


def cmd_build(args: argparse.Namespace) -> int:
    from workers.local import EventWriter, build_to_dir

    spec_path = Path(args.spec)
    with _events_sink(args.events) as sink:
        info = build_to_dir(
            spec_path, Path(args.out), EventWriter("build", sink, None if args.quiet else _echo)
        )
    if not args.quiet:
        print(
            f"built {info.kind} database {info.id[:12]} in {args.out}: {len(info.clips)} clips, "
            f"{info.frames} frames at {info.fps:g} fps"
        )
    return 0


def cmd_synth(args: argparse.Namespace) -> int:
    from workers.local import EventWriter, synth_from_dir, write_result

    with _events_sink(args.events) as sink:
        writer = EventWriter("local", sink, None if args.quiet else _echo)
        result = synth_from_dir(Path(args.request), Path(args.db), writer, args.budget)
    if result is None:
        failed = [e for e in writer.events if e.type == EventType.failed]
        msg = failed[-1].data["error"]["message"] if failed else "no result"
        raise MotionError(f"synthesis failed: {msg}")
    motion, report = result
    for note in write_result(motion, report, Path(args.out), Path(args.report) if args.report else None):
        print(f"segue: note: {note}", file=sys.stderr)
    if not args.quiet:
        print(f"wrote {args.out}: {motion.num_frames} frames at {motion.fps:g} fps, score {report.score:.6g}")
        print(quality_summary(report))
    return 0


def quality_summary(report: Report) -> str:
    """One line per reason a result is not ok (``quality: ok`` when it is)."""
    if report.ok is None:
        return "quality: not measured"
    if report.ok:
        return "quality: ok (every constraint met, plausible against the database's examples)"
    return "quality: NOT ok\n" + "\n".join(f"  - {r}" for r in report.reasons)


class _events_sink:  # noqa: N801 - a tiny context manager used like a function
    def __init__(self, path: str | None) -> None:
        self.path = path
        self.fh: Any = None

    def __enter__(self) -> Any:
        if self.path:
            self.fh = open(self.path, "w", encoding="utf-8")
        return self.fh

    def __exit__(self, *exc: object) -> None:
        if self.fh is not None:
            self.fh.close()


def cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from service.app import create_app

    settings = with_options(get_settings(), data_dir=args.data, redis_url=args.redis, workers=args.workers)
    if not is_loopback(args.host) and not settings.auth_enabled:
        print(
            f"segue: error: --host {args.host} would open the API to the network without tokens; set "
            "SEGUE_API_TOKENS (and SEGUE_ALLOWED_HOSTS) first: without tokens Segue is a single-user tool "
            "for this machine",
            file=sys.stderr,
        )
        return 2
    uvicorn.run(create_app(settings), host=args.host, port=args.port, log_level=args.log_level)
    return 0


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    import ipaddress

    if host.strip("[]").lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def cmd_worker(args: argparse.Namespace) -> int:
    from workers.redis_worker import serve

    return serve(
        with_options(get_settings(), redis_url=args.redis, data_dir=args.data, worker_name=args.name)
    )


def _add_limits(p: argparse.ArgumentParser) -> None:
    """The BVH reader's limits (``--max-joints``, ``--max-frames``)."""
    p.add_argument(
        "--max-joints", type=int, default=1024, help="refuse files with more joints (default 1024)"
    )
    p.add_argument("--max-frames", type=int, default=2_000_000, help="refuse files with more frames")


def _add_file_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The commands on one motion file: ``inspect``, ``beats``, ``convert``."""
    units = sorted(METRES_PER_UNIT)
    p = sub.add_parser("inspect", help="frames, fps, joints, height and units guess of a BVH file")
    p.add_argument("file", help="BVH file (.bvh, .bvh.gz) or sample:NAME")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--units", choices=units, help="declare the file's length unit instead of guessing")
    _add_limits(p)
    p.set_defaults(func=cmd_inspect)

    p = sub.add_parser("beats", help="motion beats of a BVH file: tempo and beat times (Kim et al. 2003)")
    p.add_argument("file", help="BVH file (.bvh, .bvh.gz) or sample:NAME")
    p.add_argument(
        "--json", action="store_true", help='print one JSON object {"period_s", "bpm", "beats_s", ...}'
    )
    p.add_argument(
        "--joints", help="comma-separated joint names or indices to analyse (default: major joints)"
    )
    p.add_argument("--positions", action="store_true", help="analyse joint positions instead of orientations")
    p.add_argument(
        "--tempo", default="40:200", help="tempo range LOW:HIGH in beats per minute (default 40:200)"
    )
    _add_limits(p)
    p.set_defaults(func=cmd_beats)

    p = sub.add_parser("convert", help="convert a BVH file by output extension: " + " ".join(OUTPUT_SUFFIXES))
    p.add_argument("input", help="BVH file (.bvh, .bvh.gz) or sample:NAME")
    p.add_argument("output", help="output file: " + ", ".join(OUTPUT_SUFFIXES))
    p.add_argument("--fps", type=float, help="resample to this frame rate (slerp rotations)")
    p.add_argument(
        "--target", default="gltf", choices=sorted(TARGETS), help="axes/handedness/units convention"
    )
    p.add_argument(
        "--units", choices=units, help="output length unit for .bvh/.npz (default: the file's own)"
    )
    p.add_argument("--in-units", choices=units, help="declare the input's length unit instead of guessing")
    p.add_argument("--frames", help="keep frames START:STOP only (Python slice, e.g. 0:240)")
    p.add_argument(
        "--ground-root", action="store_true", help="add the explicit ground root joint (always in .glb)"
    )
    p.add_argument("--quiet", "-q", action="store_true", help="print nothing on success")
    _add_limits(p)
    p.set_defaults(func=cmd_convert)


def _add_sample_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The bundled samples: ``samples`` and the ``demo``."""
    p = sub.add_parser("samples", help="list the bundled sample clips")
    p.set_defaults(func=cmd_samples)

    p = sub.add_parser(
        "demo",
        help="convert a bundled salsa clip to GLB, JSON and NPZ, and dance it to 120 BPM (rhythm engine)",
    )
    p.add_argument("--out", default="segue-demo", help="output directory (default ./segue-demo)")
    p.add_argument("--no-synth", action="store_true", help="only convert the clip (no database, no dance)")
    p.set_defaults(func=cmd_demo)


def _add_job_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Jobs in this process, on files: ``build`` and ``synth`` (the API's JSON)."""
    p = sub.add_parser("build", help="build a database from a spec file (clip paths relative to it)")
    p.add_argument("spec", help='database spec JSON, e.g. {"kind": "clips", "clips": [{"bvh": "a.bvh"}]}')
    p.add_argument("--out", required=True, help="database directory to write")
    p.add_argument("--events", help="also write the job's events as JSON lines here")
    p.add_argument("--quiet", "-q", action="store_true")
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("synth", help="run a synthesis request against a database directory")
    p.add_argument("request", help='job request JSON, e.g. {"engine": "clip", "clip": "a"}')
    p.add_argument("--db", required=True, help="database directory from segue build")
    p.add_argument("--out", required=True, help="output motion: " + ", ".join(OUTPUT_SUFFIXES))
    p.add_argument("--report", help="write the report JSON here")
    p.add_argument("--events", help="write the events as JSON lines here")
    p.add_argument("--budget", type=float, help="search budget in seconds (overrides the request's budget_s)")
    p.add_argument("--quiet", "-q", action="store_true")
    p.set_defaults(func=cmd_synth)


def _add_server_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The runtime: ``serve`` (the API) and ``worker`` (a Redis worker)."""
    p = sub.add_parser("serve", help="run the HTTP/WebSocket API (embedded workers unless --redis)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--data", help="data directory (default $SEGUE_DATA_DIR or ./segue-data)")
    p.add_argument("--redis", help="Redis URL: queue jobs for `segue worker` processes instead")
    p.add_argument("--workers", type=int, help="embedded worker processes (default 2)")
    p.add_argument("--log-level", default="info")
    p.set_defaults(func=cmd_serve)

    p = sub.add_parser("worker", help="a job worker consuming the Redis queue")
    p.add_argument("--redis", required=True, help="Redis URL, e.g. redis://127.0.0.1:6379/0")
    p.add_argument("--data", help="data directory shared with the API (default $SEGUE_DATA_DIR)")
    p.add_argument("--name", help="worker name (default host-pid)")
    p.set_defaults(func=cmd_worker)


def build_parser() -> argparse.ArgumentParser:
    """``segue``'s parser: one sub-command per job a user has."""
    ap = argparse.ArgumentParser(
        prog="segue", description="Segue: motion synthesis by example from motion capture."
    )
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_file_commands(sub)
    _add_sample_commands(sub)
    _add_job_commands(sub)
    _add_server_commands(sub)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    tune_process()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        settings = get_settings()
    except ValidationError as exc:
        print(f"segue: error: invalid SEGUE_* setting: {_validation_message(exc)}", file=sys.stderr)
        return 2
    load_plugins(settings.engine_plugins)
    try:
        return int(args.func(args))
    except ValidationError as exc:
        print(f"segue: error: invalid JSON: {_validation_message(exc)}", file=sys.stderr)
        return 2
    except JobFailure as exc:
        print(f"segue: error: {exc.message}", file=sys.stderr)
        return 2
    except (MotionError, RequestError, UnavailableError, EngineError) as exc:
        print(f"segue: error: {exc}", file=sys.stderr)
        return 2
    except json.JSONDecodeError as exc:
        print(f"segue: error: invalid JSON: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"segue: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
