"""The ``segue`` command line.

Commands::

    segue inspect FILE [--json] [--units U] [--up A]  frames, fps, joints, height, units, up axis (BVH, GLB)
    segue beats FILE [--json] [--joints A,B] [--positions] [--tempo LO:HI]   motion beats (Kim et al. 2003)
    segue beats SONG.wav [--json] [--tempo-bpm X]      music beats of a recording (WAV, FLAC, Ogg, MP3)
    segue convert IN OUT [--fps N] [--target T]   BVH -> .bvh/.bvh.gz/.glb/.json/.npz
    segue retarget MOTION --to CHARACTER --out OUT [--map MAP.json] [--rest first|zero]
           [--target T] [--root-motion root|hips|none] [--animation-only] [--events contacts]
                                                  the motion on another character (BVH or GLB/glTF skin;
                                                  a GLB character's own file with the animation added)
    segue samples                                 list the bundled samples (clips and a MIDI song)
    segue demo [--out DIR]                        convert a bundled clip and dance it (rhythm)
    segue demo ENGINE [--out DIR]                 one engine end to end on bundled clips (service.demos)
    segue build SPEC.json --out DIR               build a database (same JSON as POST /v1/databases)
    segue synth REQUEST.json --db DIR --out OUT   run a job in-process (same JSON as POST /v1/jobs)
    segue graph DIR [--json]                      a rhythm database's movement transition graph
    segue graph-edit DIR EDITS.json --out DIR2    derive a database with an edited movement graph
    segue serve [--host H] [--port P] [--redis URL] [--import DIR]   the HTTP/WebSocket API (+ embedded
                                                  workers), serving database folders segue build wrote
    segue worker --redis URL                      a Redis job worker

``FILE``/``IN`` may be ``sample:NAME`` for a bundled sample (see ``segue samples``), as may clip and
input paths in spec and request files. Bad input exits with status 2 and a one-line message naming
the problem.
"""

from __future__ import annotations

# Only the standard library at module level: ``segue --help`` and argument errors answer before
# numpy, scipy, pydantic or any engine is imported (each command imports what it needs).
import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from motion import Motion
    from motion.bvh import BvhLimits
    from schemas import JobEvent, Report

SAMPLE_PREFIX = "sample:"

UNITS = ("cm", "cmu", "cmu-scaled", "ft", "in", "m", "mm")
"""Length units the options accept (:data:`motion.units.METRES_PER_UNIT`; a test keeps them equal)."""
TARGETS = ("gltf", "godot", "unity", "unreal")
"""Export conventions (:data:`motion.export.targets.TARGETS`)."""
OUTPUT_SUFFIXES = (".bvh", ".bvh.gz", ".glb", ".json", ".npz")
"""Output formats by extension (:data:`motion.io.OUTPUT_SUFFIXES`)."""


def _resolve(path: str) -> Path:
    from motion.samples import resolve_path

    return resolve_path(path)


def _limits(args: argparse.Namespace) -> BvhLimits:
    from motion.bvh import BvhLimits

    return BvhLimits(max_joints=args.max_joints, max_frames=args.max_frames)


def inspect_summary(
    path: Path,
    motion: Motion,
    declared: str | None,
    up: str = "auto",
    timing: tuple[int, float] | None = None,
) -> dict[str, Any]:
    """The facts ``segue inspect`` reports, JSON-ready. ``declared``: the unit the user gave (else
    the sample catalogue's, :func:`motion.samples.declared_units`, else guessed); ``up``: ``y``,
    ``z`` or ``auto`` (detected: :func:`motion.units.up_axis`); ``timing``: ``(frames, fps)`` of a
    glTF file's animation (``motion`` is then its one-frame bind pose)."""
    from motion.bvh import detect_units, detect_up_axis
    from motion.samples import declared_units
    from motion.units import METRES_PER_UNIT

    axis = {"y": 1, "z": 2}.get(up) or detect_up_axis(motion)
    guess = detect_units(motion, axis)
    frames, fps = timing if timing is not None else (motion.num_frames, motion.fps)
    source = "declared" if declared else "sample" if declared_units(path) else "guess"
    if path.name.lower().endswith((".glb", ".gltf")):
        source = "gltf"  # metres, by glTF's rule
    # a guessed unit comes from the height along the up axis (the reader guessed it along Y)
    units = guess.units if source == "guess" else motion.units
    mpu = METRES_PER_UNIT.get(units, motion.metres_per_unit)
    return {
        "file": str(path),
        "name": motion.name,
        "frames": frames,
        "fps": fps,
        "duration_s": round((frames - 1) / fps if timing is not None and fps > 0 else motion.duration_s, 6),
        "joints": list(motion.skeleton.names),
        "parents": [int(p) for p in motion.skeleton.parents],
        "channels": motion.skeleton.num_channels,
        "end_sites": int(motion.skeleton.end_site_parents.size),
        "units": units,
        "units_source": source,
        "up": "yz"[axis - 1],
        "up_source": "declared" if up != "auto" else "detected",
        "height": round(guess.height, 6),
        "height_m": round(guess.height * mpu, 4),
        "units_guess": {
            "units": guess.units,
            "height_m": round(guess.height_m, 4),
            "plausible": guess.plausible,
        },
    }


UNITS_SOURCES = {
    "declared": "declared",
    "sample": "declared by the sample catalogue",
    "gltf": "glTF files are in metres",
}


def cmd_inspect(args: argparse.Namespace) -> int:
    from motion import MotionError
    from motion.io import load_motion
    from motion.retarget.character import GLTF_SUFFIXES, gltf_character, gltf_timing

    path = _resolve(args.file)
    timing = None
    if path.name.lower().endswith(GLTF_SUFFIXES):
        if args.units not in (None, "m"):
            raise MotionError(
                f"{path}: a glTF file is in metres (glTF's rule); --units {args.units} does not apply"
            )
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise MotionError(f"{path}: {exc.strerror or exc}") from None
        motion = gltf_character(raw, name=path.name.rsplit(".", 1)[0])  # the skin's bind pose
        timing = gltf_timing(raw)
    else:
        motion = load_motion(path, units=args.units, limits=_limits(args))
    info = inspect_summary(path, motion, args.units, args.up, timing)
    if args.json:
        print(json.dumps(info))
        return 0
    joints = info["joints"]
    shown = ", ".join(joints[:12]) + (f", ... (+{len(joints) - 12})" if len(joints) > 12 else "")
    guess = info["units_guess"]
    print(f"{path}")
    if timing is None and path.name.lower().endswith(GLTF_SUFFIXES):
        print("  frames     none (no animation): the skin's bind pose")
    else:
        print(f"  frames     {info['frames']} at {info['fps']:g} fps ({info['duration_s']:.2f} s)")
    print(f"  joints     {len(joints)}: {shown}")
    print(f"  channels   {info['channels']}, end sites {info['end_sites']}")
    where = " (the bind pose)" if timing is not None or info["units_source"] == "gltf" else ""
    print(
        f"  height     {info['height']:.4g} file units = {info['height_m']:.2f} m in {info['units']}{where}"
    )
    note = "" if guess["plausible"] else " (implausible: declare --units)"
    src = UNITS_SOURCES.get(info["units_source"], f"guessed from height{note}")
    print(f"  units      {info['units']} ({src})")
    print(f"  up axis    {info['up'].upper()} ({info['up_source']})")
    return 0


def _tempo_range(text: str) -> tuple[float, float]:
    from motion import MotionError

    lo, sep, hi = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return float(lo), float(hi)
    except ValueError:
        raise MotionError(f"--tempo {text!r}: expected LOW:HIGH beats per minute, e.g. 40:200") from None


def _beats_audio(path: Path, args: argparse.Namespace) -> int:
    """``segue beats`` on a recording: music beats (:mod:`workers.audio`)."""
    from workers.audio import recording_beats

    info = recording_beats(path, args.tempo_bpm)
    if args.json:
        print(json.dumps(info))
        return 0
    print(f"{path}")
    beats = info["beats_s"]
    print(f"  duration   {info['duration_s']:.2f} s")
    sure = "" if info["tempo_confidence"] is None else f" (confidence {info['tempo_confidence']:.2f})"
    print(f"  tempo      {info['tempo_bpm']:.1f} bpm{sure}")
    down = "none found" if info["downbeat_s"] is None else f"first at {info['downbeat_s']:.3f} s"
    print(f"  beats      {len(beats)}, downbeat {down}")
    shown = ", ".join(f"{t:.3f}" for t in beats[:16])
    print(f"  times (s)  {shown}{', ...' if len(beats) > 16 else ''}")
    return 0


def cmd_beats(args: argparse.Namespace) -> int:
    from motion.beats import detect_beats
    from motion.io import load_motion
    from schemas.rhythm import AUDIO_SUFFIXES

    path = _resolve(args.file)
    if str(path).lower().endswith(AUDIO_SUFFIXES):
        return _beats_audio(path, args)
    if args.tempo_bpm is not None:
        raise OSError("--tempo-bpm is a hint for recordings (.wav .flac .ogg .mp3); use --tempo for motion")
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
        "tempo_bpm": round(beats.bpm, 4),
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


def _without_reference(motion: Any, source: str, args: argparse.Namespace) -> tuple[Any, list[str]]:
    """The motion without the reference-pose frames it starts with (:mod:`motion.refpose`), and the
    note to print. Bundled ``sample:`` clips are cleaned by default (``--keep-reference`` keeps the
    frames); a user's file keeps its frame count unless ``--drop-reference`` asks (a note says when
    such frames were found)."""
    from motion.refpose import reference_lead, without_reference_lead

    drop = args.drop_reference or (source.startswith("sample:") and not args.keep_reference)
    if drop:
        motion, dropped = without_reference_lead(motion)
        if not dropped:
            return motion, []
        s = "s" if dropped > 1 else ""
        return motion, [
            f"dropped the first {dropped} frame{s} (a reference pose and the blend out of it; "
            "--keep-reference keeps them)"
        ]
    found = reference_lead(motion)
    if not found:
        return motion, []
    s = "s" if found > 1 else ""
    return motion, [
        f"the first {found} frame{s} look like a reference pose blending into the capture: kept "
        "(--drop-reference drops them)"
    ]


def cmd_convert(args: argparse.Namespace) -> int:
    from motion import MotionError
    from motion.export.events import parse_kinds
    from motion.ground import add_ground_root
    from motion.io import load_motion, save_motion
    from motion.resample import resample

    src = _resolve(args.input)
    motion = load_motion(src, units=args.in_units, limits=_limits(args))
    reference: list[str] = []
    if not args.frames:
        motion, reference = _without_reference(motion, args.input, args)
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
    events = parse_kinds(args.events) if args.events else ()
    if set(events) - {"contacts"}:
        raise MotionError("a motion file has contact events only; beats and labels come with results")
    notes = save_motion(
        motion, args.output, target=args.target, units=args.units, in_place=args.in_place, events=events
    )
    for note in reference + notes:
        print(f"segue: note: {note}", file=sys.stderr)
    if not args.quiet:
        print(
            f"wrote {args.output}: {motion.num_frames} frames at {motion.fps:g} fps, "
            f"{motion.num_joints} joints, target {args.target} ({time.perf_counter() - t0:.2f} s)"
        )
    return 0


def cmd_retarget(args: argparse.Namespace) -> int:
    from motion import MotionError
    from motion.export.bind import bound_glb
    from motion.export.events import contact_events, parse_kinds
    from motion.export.glb import write_glb
    from motion.io import load_motion, save_motion
    from motion.retarget import correspond, retarget
    from motion.retarget.character import GLTF_SUFFIXES, load_character
    from motion.retarget.rootmotion import default_root_motion
    from motion.units import METRES_PER_UNIT

    name_map = None
    if args.map:
        try:
            name_map = json.loads(Path(args.map).read_text(encoding="utf-8"))
        except OSError as exc:
            raise MotionError(f"{args.map}: cannot read the joint map: {exc.strerror or exc}") from None
        if not isinstance(name_map, dict):
            raise MotionError(
                f"{args.map}: the joint map must be a JSON object {{source joint: character joint}}"
            )
    to = _resolve(args.to)
    gltf_character = to.name.lower().endswith(GLTF_SUFFIXES)
    glb_out = args.out.lower().endswith(".glb")
    if args.animation_only and not (gltf_character and glb_out):
        raise MotionError("--animation-only is for a glTF/GLB character written to a .glb")
    kinds = parse_kinds(args.events) if args.events else ()
    if set(kinds) - {"contacts"}:
        raise MotionError("a retargeted motion has contact events only; beats and labels come with results")
    motion = load_motion(_resolve(args.motion), units=args.in_units, limits=_limits(args))
    motion, reference = _without_reference(motion, args.motion, args)
    character = load_character(to, rest=args.rest, limits=_limits(args))
    t0 = time.perf_counter()
    corr = correspond(motion.skeleton, character.skeleton, name_map)
    mode = args.root_motion or default_root_motion(args.target, corr.target_roles["Hips"])
    out = retarget(motion, character, name_map=name_map, plant=not args.no_plant, root_motion=mode)
    notes: list[str] = []
    if glb_out:
        events = contact_events(out) if kinds else None
        if gltf_character:  # the character's own file, with the animation added
            data = bound_glb(
                to.read_bytes(), out, animation_only=args.animation_only, events=events, base_dir=to.parent
            )
            try:
                Path(args.out).write_bytes(data)
            except OSError as exc:
                raise MotionError(f"cannot write {args.out}: {exc.strerror or exc}") from None
        else:  # exactly the BVH character's hierarchy (no ground joint added)
            write_glb(out, args.out, ground_root=False, events=events)
    else:
        # the character's own units, exactly
        keep = out.units in METRES_PER_UNIT
        notes = save_motion(out, args.out, units=out.units if keep else None, events=kinds)
    for note in reference + notes:
        print(f"segue: note: {note}", file=sys.stderr)
    if not args.quiet:
        root = (
            character.skeleton.names[0]
            if mode in ("root", "none")
            else character.skeleton.names[corr.target_roles["Hips"]]
        )
        print(
            f"wrote {args.out}: {out.num_frames} frames at {out.fps:g} fps on {character.name or args.to} "
            f"({out.num_joints} joints, {len(corr.pairs)} driven; "
            f"{corr.source_preset} -> {corr.target_preset}, "
            f"units {out.units}; root motion {mode}"
            + ("" if mode == "none" else f" on {root!r}")
            + f"; {time.perf_counter() - t0:.2f} s)"
        )
    return 0


def cmd_samples(args: argparse.Namespace) -> int:
    from motion.samples import SAMPLES, sample_path

    for name in SAMPLES:
        print(f"{SAMPLE_PREFIX}{name}\t{sample_path(name)}")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from .demos import DEMOS, run_classic, run_demo

    out = Path(args.out)
    if args.engine is None:
        run_classic(out, synth=not args.no_synth)
        return 0
    names = list(DEMOS) if args.engine == "all" else [args.engine]
    results = [run_demo(name, out) for name in names]
    if len(results) > 1:
        done = [f"{r.name} {'ok' if r.ok else 'NOT ok'} {r.total_s:.1f} s" for r in results]
        print("demos: " + ", ".join(done))
    return 0


def _validation_message(exc: Any) -> str:
    """A pydantic ``ValidationError`` in one line (its first five problems)."""
    parts = []
    for err in exc.errors()[:5]:
        where = ".".join(str(p) for p in err["loc"]) or "(top level)"
        parts.append(f"{where}: {err['msg']}")
    more = f" (+{len(exc.errors()) - 5} more)" if len(exc.errors()) > 5 else ""
    return "; ".join(parts) + more


def _echo(event: JobEvent) -> None:
    from schemas import EventType

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


def _load_plugins() -> None:
    """The engine plugins named by the settings (``SEGUE_ENGINE_PLUGINS``)."""
    from engines.registry import load_plugins
    from workers.settings import get_settings

    load_plugins(get_settings().engine_plugins)


def cmd_build(args: argparse.Namespace) -> int:
    from workers.local import EventWriter, build_to_dir

    _load_plugins()

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
        for line in kept_lines(Path(args.out) / "data.npz"):
            print(line)
    return 0


def kept_lines(npz: Path, limit: int = 20) -> list[str]:
    """What a graph build kept and left out (its report in the database's ``data.npz``), one line
    per dropped clip up to ``limit``; no lines for other kinds of database."""
    import numpy as np

    from workers.summary import graph_kept

    with np.load(npz, allow_pickle=False) as z:
        if "graph.report" not in z.files:
            return []
        kept = graph_kept(z["graph.report"])
    if kept is None:
        return []
    total = kept.kept_frames + kept.dropped_frames
    lines = [
        f"graph ({kept.candidates} transitions): kept {kept.kept_clips} clips, {kept.kept_frames} of {total} "
        f"frames ({kept.moving_frames} in locomotion), {kept.leaf_edges} transitions; "
        f"left out {len(kept.dropped)} clips, {kept.dropped_frames} frames" + (":" if kept.dropped else "")
    ]
    lines += [f"  {d.clip} ({d.frames} frames): {d.reason}" for d in kept.dropped[:limit]]
    if len(kept.dropped) > limit:
        lines.append(f"  ... and {len(kept.dropped) - limit} more (GET /v1/databases/{{id}}: summary.graph)")
    return lines


def cmd_synth(args: argparse.Namespace) -> int:
    from motion import MotionError
    from schemas import EventType
    from workers.local import EventWriter, synth_from_dir, write_result

    _load_plugins()

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


def cmd_graph(args: argparse.Namespace) -> int:
    from workers.graph_edits import graph_of_dir

    graph = graph_of_dir(Path(args.db))
    if args.json:
        print(graph.model_dump_json(indent=2))
        return 0
    parent = f", derived from {graph.derived_from.parent[:12]}" if graph.derived_from else ""
    print(
        f"database {graph.database[:12]}{parent}: {len(graph.groups)} groups, "
        f"{len(graph.transitions)} transitions, {graph.beats_per_movement} beats per movement"
        + ("" if graph.strongly_connected else " (NOT strongly connected)")
    )
    if graph.start_only_groups or graph.unreachable_groups:
        print(f"start-only groups {graph.start_only_groups}, unreachable groups {graph.unreachable_groups}")
    for g in graph.groups:
        r = g.representative
        mirror = " mirrored" if r.mirrored else ""
        print(
            f"group {g.id:3d}: {g.size:3d} movements, e.g. {r.clip}{mirror} frames "
            f"{r.start_frame}-{r.end_frame} ({r.start_s:.2f}-{r.end_s:.2f} s)"
        )
    for t in graph.transitions:
        tag = "" if t.learned else "  (added)"
        print(
            f"{t.source:3d} -> {t.target:3d}  P {t.probability:.3f}  kinematic {t.kinematic:.3f}  "
            f"behavioural {t.behavioural:.3f}{tag}"
        )
    return 0


def cmd_graph_edit(args: argparse.Namespace) -> int:
    from schemas.rhythm_graph import GraphEdits
    from workers.graph_edits import derive_dir

    data = json.loads(Path(args.edits).read_bytes())
    body = GraphEdits.model_validate({"edits": data} if isinstance(data, list) else data)
    info = derive_dir(Path(args.db), body, Path(args.out))
    if not args.quiet:
        print(f"derived database {info.id[:12]} in {args.out}: {len(body.edits)} edits of {args.db}")
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
    from service.app import create_app
    from service.server import serve
    from workers.settings import get_settings, with_options

    settings = with_options(get_settings(), data_dir=args.data, redis_url=args.redis, workers=args.workers)
    if not is_loopback(args.host) and not settings.auth_enabled:
        print(
            f"segue: error: --host {args.host} would open the API to the network without tokens; set "
            "SEGUE_API_TOKENS (and SEGUE_ALLOWED_HOSTS) first: without tokens Segue is a single-user tool "
            "for this machine",
            file=sys.stderr,
        )
        return 2
    if args.imports:
        import_databases(settings, [Path(d) for d in args.imports])
    if not args.no_warm and not settings.redis_url:
        start_warming()  # the embedded workers run jobs: compile their kernels off the request path
    serve(create_app(settings), settings, args.host, args.port, args.log_level)
    return 0


def import_databases(settings: Any, folders: list[Path]) -> None:
    """``segue serve --import DIR``: put databases ``segue build`` wrote into the server's store, under
    the id the API gives the same clips and spec, held by every principal (the tokenless user and
    each ``SEGUE_API_TOKENS`` name). Raises ``workers.imports.ImportFailure`` naming a bad folder."""
    from service.deps import LOCAL, token_table
    from workers.imports import import_database_dir
    from workers.store import Store

    store = Store(settings.data_dir)
    owners = [LOCAL, *(name for name, _ in token_table(settings))]
    for folder in folders:
        info, new = import_database_dir(store, folder, owners)
        done = "imported" if new else "already held"
        print(
            f"segue: {done} {info.kind} database {info.id[:12]} ({len(info.clips)} clips) from {folder}",
            file=sys.stderr,
        )


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
    from workers.settings import get_settings, with_options

    settings = with_options(get_settings(), redis_url=args.redis, data_dir=args.data, worker_name=args.name)
    if not settings.redis_url:
        print(
            "segue: error: a worker needs a Redis URL: give --redis URL or set SEGUE_REDIS_URL",
            file=sys.stderr,
        )
        return 2
    return serve(settings, warm=not args.no_warm)


def cmd_warm(args: argparse.Namespace) -> int:
    from engines.registry import warm_compiled
    from motion.jitcache import configure

    print(f"numba cache: {configure()}")
    warm_compiled(print, force=args.force)
    return 0


def start_warming() -> None:
    """``segue warm`` in a background process (niced, output to this terminal): the compiled
    kernels are ready before the first control job, without holding this process's GIL."""
    import os
    import subprocess

    def lower_priority() -> None:
        os.nice(5)

    subprocess.Popen(
        [sys.executable, "-m", "service.cli", "warm"],
        stdout=2,  # this process's standard error, whatever object sys.stderr is now
        stdin=subprocess.DEVNULL,
        preexec_fn=lower_priority if hasattr(os, "nice") else None,
    )


class _Version(argparse.Action):
    """``--version``: the installed distribution's version, looked up only when asked."""

    def __init__(self, option_strings: Sequence[str], dest: str, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=help)

    def __call__(self, parser: argparse.ArgumentParser, *args: object) -> None:
        from importlib.metadata import PackageNotFoundError, version

        try:
            text = version("segue")
        except PackageNotFoundError:
            text = "unknown (not installed; run pip install -e .)"
        print(f"segue {text}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="segue", description="Segue: motion synthesis by example from motion capture."
    )
    ap.add_argument("--version", action=_Version, help="print the installed version of Segue and exit")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, help: str, description: str | None = None) -> argparse.ArgumentParser:
        """A subcommand whose ``--help`` opens with a description (its one-line ``help`` unless given)."""
        return sub.add_parser(name, help=help, description=description or help[0].upper() + help[1:] + ".")

    def reference_options(p: argparse.ArgumentParser) -> None:
        ref = p.add_mutually_exclusive_group()
        ref.add_argument(
            "--keep-reference",
            action="store_true",
            help="keep the reference-pose frames a sample:NAME clip starts with (CMU-Daz: a T-pose "
            "blending into the capture; dropped from samples by default)",
        )
        ref.add_argument(
            "--drop-reference",
            action="store_true",
            help="drop the reference-pose frames a file starts with (a file keeps its frame count by "
            "default; a note says when it starts with such frames)",
        )

    def limits(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--max-joints", type=int, default=1024, help="refuse files with more joints (default 1024)"
        )
        p.add_argument("--max-frames", type=int, default=2_000_000, help="refuse files with more frames")

    from .demos import DEMOS

    units = sorted(UNITS)
    p = command("inspect", help="frames, fps, joints, height, units and up axis of a BVH or glTF/GLB file")
    p.add_argument("file", help="BVH file (.bvh, .bvh.gz), glTF file (.glb, .gltf) or sample:NAME")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--units", choices=units, help="declare the file's length unit instead of guessing")
    p.add_argument(
        "--up",
        choices=("auto", "y", "z"),
        default="auto",
        help="the file's vertical axis, for the height (default: detected; Segue's Unreal BVH is Z up)",
    )
    limits(p)
    p.set_defaults(func=cmd_inspect)

    p = command(
        "beats",
        help="motion beats of a BVH file (Kim et al. 2003) or music beats of a recording (WAV FLAC Ogg MP3)",
    )
    p.add_argument("file", help="BVH file (.bvh, .bvh.gz), sample:NAME, or a .wav/.flac/.ogg/.mp3 recording")
    p.add_argument(
        "--json",
        action="store_true",
        help='print one JSON object {"beats_s", ...} ("bpm" for motion, "tempo_bpm" for a recording)',
    )
    p.add_argument(
        "--tempo-bpm", type=float, default=None, help="recordings: a hint of the tempo, beats per minute"
    )
    p.add_argument(
        "--joints", help="comma-separated joint names or indices to analyse (default: major joints)"
    )
    p.add_argument("--positions", action="store_true", help="analyse joint positions instead of orientations")
    p.add_argument(
        "--tempo", default="40:200", help="tempo range LOW:HIGH in beats per minute (default 40:200)"
    )
    limits(p)
    p.set_defaults(func=cmd_beats)

    p = command("convert", help="convert a BVH file by output extension: " + " ".join(OUTPUT_SUFFIXES))
    p.add_argument("input", help="BVH file (.bvh, .bvh.gz) or sample:NAME")
    p.add_argument("output", help="output file: " + ", ".join(OUTPUT_SUFFIXES))
    p.add_argument("--fps", type=float, help="resample to this frame rate (slerp rotations)")
    p.add_argument(
        "--target", default="gltf", choices=sorted(TARGETS), help="axes/handedness/units convention"
    )
    p.add_argument(
        "--units",
        choices=units,
        help="output length unit of .bvh/.json/.npz (default: the target's, m or cm for unreal; "
        ".npz keeps the file's own for gltf/godot; .glb is always m)",
    )
    p.add_argument("--in-units", choices=units, help="declare the input's length unit instead of guessing")
    p.add_argument("--frames", help="keep frames START:STOP only (Python slice, e.g. 0:240)")
    p.add_argument(
        "--ground-root", action="store_true", help="add the explicit ground root joint (always in .glb)"
    )
    p.add_argument(
        "--in-place",
        action="store_true",
        help=".glb: the body stays over the origin; the root motion stays on the ground joint",
    )
    p.add_argument("--events", help="contacts: foot-contact events in .glb extras / .json events")
    reference_options(p)
    p.add_argument("--quiet", "-q", action="store_true", help="print nothing on success")
    limits(p)
    p.set_defaults(func=cmd_convert)

    p = command("retarget", help="put a motion on another character (BVH or GLB/glTF skin)")
    p.add_argument("motion", help="the motion: BVH file (.bvh, .bvh.gz) or sample:NAME")
    p.add_argument(
        "--to", required=True, help="the character: BVH (.bvh, .bvh.gz, sample:NAME) or .glb/.gltf skin"
    )
    p.add_argument("--out", required=True, help="output file: " + ", ".join(OUTPUT_SUFFIXES))
    p.add_argument(
        "--map", help='JSON joint map {"source joint or role": "character joint"} (adds to the presets)'
    )
    p.add_argument(
        "--rest",
        default="first",
        choices=("first", "zero"),
        help="the BVH character's rest pose: its first frame (default) or zero rotations",
    )
    p.add_argument("--in-units", choices=units, help="declare the motion's length unit instead of guessing")
    p.add_argument("--no-plant", action="store_true", help="skip the leg IK that keeps planted feet planted")
    p.add_argument(
        "--target",
        default="gltf",
        choices=sorted((*TARGETS, "blender")),
        help="the engine whose root-motion convention to follow: unreal, godot, blender, gltf on the "
        "root bone at the floor; unity on the hips (the file keeps the character's axes and units)",
    )
    p.add_argument(
        "--root-motion",
        choices=("root", "hips", "none"),
        help="where the root motion goes: the bone above the hips (root), the hips, or none (in place); "
        "default: the --target's convention",
    )
    p.add_argument(
        "--animation-only",
        action="store_true",
        help="glTF character to .glb: the skeleton and animation only (binds by bone names), no mesh",
    )
    p.add_argument("--events", help="contacts: foot-contact events in .glb extras / .json events")
    reference_options(p)
    p.add_argument("--quiet", "-q", action="store_true", help="print nothing on success")
    limits(p)
    p.set_defaults(func=cmd_retarget)

    p = command(
        "samples",
        help="list the bundled sample clips",
        description="List the bundled samples (motion clips and a MIDI song) as sample:NAME and their paths; "
        "every FILE argument, spec and request accepts sample:NAME.",
    )
    p.set_defaults(func=cmd_samples)

    p = command(
        "demo",
        help="without ENGINE: convert a bundled salsa clip to GLB, JSON and NPZ and dance it to 120 BPM; "
        "with ENGINE: that engine end to end on bundled clips, into DIR/ENGINE/",
    )
    p.add_argument(
        "engine",
        nargs="?",
        choices=[*DEMOS, "all"],
        metavar="ENGINE",
        help=f"one of {', '.join(DEMOS)} or all: BVH, GLB and the report in DIR/ENGINE/",
    )
    p.add_argument("--out", default="segue-demo", help="output directory DIR (default ./segue-demo)")
    p.add_argument("--no-synth", action="store_true", help="without ENGINE: only convert the clip (no dance)")
    p.set_defaults(func=cmd_demo)

    p = command("build", help="build a database from a spec file (clip paths relative to it)")
    p.add_argument("spec", help='database spec JSON, e.g. {"kind": "clips", "clips": [{"bvh": "a.bvh"}]}')
    p.add_argument("--out", required=True, help="database directory to write")
    p.add_argument("--events", help="also write the job's events as JSON lines here")
    p.add_argument("--quiet", "-q", action="store_true", help="print nothing on success")
    p.set_defaults(func=cmd_build)

    p = command("synth", help="run a synthesis request against a database directory")
    p.add_argument("request", help='job request JSON, e.g. {"engine": "clip", "clip": "a"}')
    p.add_argument("--db", required=True, help="database directory from segue build")
    p.add_argument("--out", required=True, help="output motion: " + ", ".join(OUTPUT_SUFFIXES))
    p.add_argument("--report", help="write the report JSON here")
    p.add_argument("--events", help="write the events as JSON lines here")
    p.add_argument(
        "--budget",
        type=float,
        help="time cap of the search, seconds (overrides the request's budget_s; the request sets the work)",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="print nothing on success")
    p.set_defaults(func=cmd_synth)

    p = command("graph", help="a rhythm database's movement transition graph (groups, transitions)")
    p.add_argument("db", help="rhythm database directory from segue build (or segue graph-edit)")
    p.add_argument("--json", action="store_true", help="print the graph as JSON (GET /v1/databases/ID/graph)")
    p.set_defaults(func=cmd_graph)

    p = command(
        "graph-edit", help="derive a rhythm database whose movement graph is edited (connect, cut, weight)"
    )
    p.add_argument("db", help="rhythm database directory")
    p.add_argument(
        "edits", help='edits JSON: {"edits": [{"op": "cut", "source": 0, "target": 3}, ...]} or the list'
    )
    p.add_argument("--out", required=True, help="derived database directory to write")
    p.add_argument("--quiet", "-q", action="store_true", help="print nothing on success")
    p.set_defaults(func=cmd_graph_edit)

    p = command("serve", help="run the HTTP/WebSocket API (embedded workers unless --redis)")
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1; another needs SEGUE_API_TOKENS)",
    )
    p.add_argument("--port", type=int, default=8000, help="TCP port to listen on (default 8000)")
    p.add_argument("--data", help="data directory (default $SEGUE_DATA_DIR or ./segue-data)")
    p.add_argument("--redis", help="Redis URL: queue jobs for `segue worker` processes instead")
    p.add_argument("--workers", type=int, help="embedded worker processes (default 2)")
    p.add_argument(
        "--import",
        dest="imports",
        action="append",
        metavar="DIR",
        help="serve a database folder that `segue build` wrote (under the same id the API gives it); "
        "repeat for more",
    )
    p.add_argument(
        "--log-level",
        default="info",
        choices=("critical", "error", "warning", "info", "debug", "trace"),
        help="server log level (default info)",
    )
    p.add_argument(
        "--no-warm", action="store_true", help="do not compile the control kernels in the background at start"
    )
    p.set_defaults(func=cmd_serve)

    p = command(
        "worker",
        help="a job worker consuming the Redis queue",
        description="A job worker consuming the Redis queue that `segue serve --redis` feeds.",
    )
    p.add_argument(
        "--redis", help="Redis URL, e.g. redis://127.0.0.1:6379/0 (default $SEGUE_REDIS_URL; one is needed)"
    )
    p.add_argument("--data", help="data directory shared with the API (default $SEGUE_DATA_DIR)")
    p.add_argument("--name", help="worker name (default host-pid)")
    p.add_argument(
        "--no-warm", action="store_true", help="do not compile the control kernels before the first job"
    )
    p.set_defaults(func=cmd_worker)

    p = command(
        "warm",
        help="compile the control engine's kernels into numba's cache (~15 s of CPU once per install; "
        "serve and worker do it at start)",
    )
    p.add_argument("--force", action="store_true", help="run the kernels even if this cache was warmed")
    p.set_defaults(func=cmd_warm)
    return ap


def _user_error(exc: Exception) -> str | None:
    """The one-line message for an error caused by the input (a bad file, JSON, option value or
    request), None for a bug. Only modules already imported are consulted (an error of a module
    never imported cannot have been raised)."""
    mods = sys.modules
    if isinstance(exc, json.JSONDecodeError):
        return f"invalid JSON: {exc}"
    if "pydantic" in mods and isinstance(exc, mods["pydantic"].ValidationError):
        return f"invalid JSON: {_validation_message(exc)}"
    if "workers.execute" in mods and isinstance(exc, mods["workers.execute"].JobFailure):
        return str(exc.message)
    known: list[type] = [OSError]
    for module, name in (
        ("motion.errors", "MotionError"),
        ("schemas.jobs", "RequestError"),
        ("engines.registry", "UnavailableError"),
        ("engines.base", "EngineError"),
        ("workers.inputs", "InputError"),
        ("workers.imports", "ImportFailure"),
    ):
        if module in mods:
            known.append(getattr(mods[module], name))
    return str(exc) if isinstance(exc, tuple(known)) else None


SIGPIPE_STATUS = 128 + 13
"""The exit status of a Unix tool whose reader went away (``yes | head``: SIGPIPE)."""


def _reader_gone() -> int:
    """Stdout's reader closed the pipe (``segue graph DB | head -4``): end quietly, as Unix tools do.
    Stdout is pointed at /dev/null so that the interpreter's final flush does not fail again (the
    recipe of the Python docs, "Note on SIGPIPE")."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout is not a file (an embedding program's stream)
        pass
    return SIGPIPE_STATUS


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from motion.allocator import tune_process

    tune_process()
    try:
        status = int(args.func(args))
        sys.stdout.flush()  # a closed pipe shows here, not at exit
        return status
    except BrokenPipeError:
        return _reader_gone()
    except Exception as exc:
        message = _user_error(exc)
        if message is None:
            raise
        print(f"segue: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
