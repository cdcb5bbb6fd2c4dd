"""``segue inspect``, ``beats``, ``convert``, ``retarget`` and ``samples``: motion files in and out.

Only the standard library at module level (each command imports what it needs).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..summaries import inspect_summary

if TYPE_CHECKING:
    from motion.bvh import BvhLimits


SAMPLE_PREFIX = "sample:"

UNITS = ("cm", "cmu", "cmu-scaled", "ft", "in", "m", "mm")
"""Length units the options accept (:data:`motion.units.METRES_PER_UNIT`; a test keeps them equal)."""
TARGETS = ("gltf", "godot", "unity", "unreal")
"""Export conventions (:data:`motion.export.targets.TARGETS`)."""
OUTPUT_SUFFIXES = (".bvh", ".bvh.gz", ".glb", ".json", ".npz")
"""Output formats by extension (:data:`motion.io.OUTPUT_SUFFIXES`)."""
DEFAULT_MAX_JOINT_FRAMES = 20_000_000
"""Default ``--max-joint-frames`` (:data:`motion.bvh.DEFAULT_MAX_JOINT_FRAMES`; a test keeps them equal)."""
FEET_MODES = ("lock", "grounding", "free")
"""What ``--feet`` does to the feet (:data:`motion.retarget.grounding.FEET_MODES`)."""


def _resolve(path: str) -> Path:
    from motion.samples import resolve_path

    return resolve_path(path)


def _limits(args: argparse.Namespace) -> BvhLimits:
    from motion.bvh import BvhLimits

    return BvhLimits(
        max_joints=args.max_joints, max_frames=args.max_frames, max_joint_frames=args.max_joint_frames
    )


def _animation(args: argparse.Namespace, name: str = "animation") -> str | int | None:
    """The ``--animation`` option: an index when it is a number, else a name (None: not given)."""
    value = getattr(args, name, None)
    if value is None:
        return None
    return int(value) if str(value).isdigit() else str(value)


def _read(path: Path, args: argparse.Namespace, units: str | None, animation: str | int | None = None) -> Any:
    """The motion of a BVH or glTF file (:func:`motion.io.load_motion`), its reader's warnings
    printed to stderr as ``segue: warning: FILE:LINE: ...``."""
    from motion.io import load_motion

    warnings: list[Any] = []
    motion = load_motion(path, units=units, limits=_limits(args), animation=animation, warnings=warnings)
    print_warnings(warnings)
    return motion


def _picked(animations: list[Any], wanted: str | int | None) -> str:
    """The name of the animation ``--animation`` reads (the first by default; by name, else index),
    among those :func:`motion.gltf.gltf_animations` listed (the read itself refused a missing one)."""
    names = [a.name for a in animations]
    if wanted is None:
        return str(names[0])
    if isinstance(wanted, str) and wanted in names:
        return wanted
    return str(names[int(wanted)])


def print_warnings(warnings: list[Any]) -> None:
    """Each reader warning on its own stderr line (what the file needed to be read)."""
    for w in warnings:
        print(f"segue: warning: {w}", file=sys.stderr)


UNITS_SOURCES = {
    "declared": "declared",
    "sample": "declared by the sample catalogue",
    "gltf": "glTF files are in metres",
}


def _inspect_database(db_dir: Path, as_json: bool) -> int:
    """``segue inspect DIR`` of a folder ``segue build`` wrote: its summary (what ``GET
    /v1/databases/{id}`` says of it once served), every clip a graph build left out included."""
    from workers.summary import database_dir_summary

    from .jobs import kept_lines

    summary = database_dir_summary(db_dir)
    if as_json:
        print(summary.model_dump_json())
        return 0
    frames = sum(c.frames for c in summary.clips)
    sk = summary.skeleton
    print(f"{db_dir}")
    print(f"  kind       {summary.kind}")
    seconds = frames / summary.fps
    print(f"  clips      {len(summary.clips)}, {frames} frames at {summary.fps:g} fps ({seconds:.1f} s)")
    print(
        f"  skeleton   {len(sk.joints)} joints, hips {sk.hips}" + (" (static root)" if sk.static_root else "")
    )
    shown = ", ".join(summary.labels[:12]) + (
        f", ... (+{len(summary.labels) - 12})" if len(summary.labels) > 12 else ""
    )
    print(f"  labels     {len(summary.labels)}" + (f": {shown}" if shown else ""))
    for line in kept_lines(db_dir, limit=None, summary=summary):
        print(f"  {line}")
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    from motion import MotionError
    from motion.gltf import GLTF_SUFFIXES, gltf_animations
    from motion.retarget.character import gltf_character

    if not args.file.startswith(SAMPLE_PREFIX) and Path(args.file).is_dir():
        db_dir = Path(args.file)
        if not (db_dir / "spec.json").is_file() or not (db_dir / "data.npz").is_file():
            raise MotionError(
                f"{db_dir}: a folder, not a database segue build wrote (no spec.json and data.npz)"
            )
        return _inspect_database(db_dir, args.json)
    path = _resolve(args.file)
    animations: list[Any] | None = None
    warnings: list[Any] = []
    if path.name.lower().endswith(GLTF_SUFFIXES):
        if args.units not in (None, "m"):
            raise MotionError(
                f"{path}: a glTF file is in metres (glTF's rule); --units {args.units} does not apply"
            )
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise MotionError(f"{path}: {exc.strerror or exc}") from None
        animations = gltf_animations(raw, base_dir=path.parent, source=str(path))
        if animations:
            from motion.io import load_motion

            motion = load_motion(path, limits=_limits(args), animation=_animation(args), warnings=warnings)
        else:
            if args.animation is not None:
                raise MotionError(f"{path}: the file has no animation (--animation {args.animation})")
            motion = gltf_character(raw, name=path.name.rsplit(".", 1)[0])  # the skin's bind pose
    else:
        if args.animation is not None:
            raise MotionError(f"{path}: --animation is for glTF files; a BVH file holds one motion")
        from motion.io import load_motion

        motion = load_motion(path, units=args.units, limits=_limits(args), warnings=warnings)
    info = inspect_summary(path, motion, args.units, args.up)
    info["warnings"] = [w.message for w in warnings]
    if animations is not None:
        info["animations"] = [
            {"index": a.index, "name": a.name, "frames": a.frames, "fps": a.fps, "duration_s": a.duration_s}
            for a in animations
        ]
        info["animation"] = _picked(animations, _animation(args)) if animations else None
    if args.json:
        print(json.dumps(info))
        return 0
    print_warnings(warnings)
    joints = info["joints"]
    shown = ", ".join(joints[:12]) + (f", ... (+{len(joints) - 12})" if len(joints) > 12 else "")
    guess = info["units_guess"]
    print(f"{path}")
    if animations is not None:
        n = len(animations)
        print(f"  animations {n}" + (": none (the skin's bind pose is shown)" if not n else ""))
        for a in animations:
            mark = "*" if a.name == info["animation"] else " "
            print(
                f"   {mark}{a.index:>2} {a.name!r}: {a.frames} frames at {a.fps:g} fps ({a.duration_s:.2f} s)"
            )
        if n > 1:
            print("             (* the one read below; --animation NAME or INDEX reads another)")
    if animations == []:
        print("  frames     none (no animation): the skin's bind pose")
    else:
        print(f"  frames     {info['frames']} at {info['fps']:g} fps ({info['duration_s']:.2f} s)")
    print(f"  joints     {len(joints)}: {shown}")
    print(f"  channels   {info['channels']}, end sites {info['end_sites']}")
    where = " (the bind pose)" if animations == [] else ""
    in_file = "" if info["units"] == "m" else f" ({info['height']:.4g} {info['units']})"
    print(f"  height     {info['height_m']:.2f} m{in_file}, standing{where}")
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
    from schemas.rhythm import AUDIO_SUFFIXES

    path = _resolve(args.file)
    if str(path).lower().endswith(AUDIO_SUFFIXES):
        return _beats_audio(path, args)
    if args.tempo_bpm is not None:
        raise OSError("--tempo-bpm is a hint for recordings (.wav .flac .ogg .mp3); use --tempo for motion")
    motion = _read(path, args, None, _animation(args))
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
    what = "the first frame looks" if found == 1 else f"the first {found} frames look"
    them = "it" if found == 1 else "them"
    return motion, [
        f"{what} like a reference pose blending into the capture: kept (--drop-reference drops {them})"
    ]


def cmd_convert(args: argparse.Namespace) -> int:
    from motion import MotionError
    from motion.export.events import parse_kinds
    from motion.ground import add_ground_root
    from motion.io import save_motion
    from motion.resample import resample

    src = _resolve(args.input)
    motion = _read(src, args, args.in_units, _animation(args))
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
    if args.feet != "free":
        from motion.retarget.legik import feet_on_floor

        motion = feet_on_floor(motion, args.feet)
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
    from motion.bvh import height_m
    from motion.export.bind import bound_glb
    from motion.export.events import contact_events, parse_kinds
    from motion.export.glb import write_glb
    from motion.io import save_motion
    from motion.retarget import correspond, retarget
    from motion.retarget.character import GLTF_SUFFIXES, load_character
    from motion.retarget.legik import character_soles, foot_groups_of, sole_floor
    from motion.retarget.report import feet_report, sole_plants
    from motion.retarget.rootmotion import default_root_motion
    from motion.skinning import read_skinned_mesh
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
    motion = _read(_resolve(args.motion), args, args.in_units, _animation(args))
    motion, reference = _without_reference(motion, args.motion, args)
    character = load_character(to, rest=args.rest, limits=_limits(args))
    mesh = read_skinned_mesh(to.read_bytes(), base_dir=to.parent) if gltf_character else None
    t0 = time.perf_counter()
    corr = correspond(motion.skeleton, character.skeleton, name_map)
    for warning in corr.warnings:
        print(f"segue: warning: {warning}", file=sys.stderr)
    mode = args.root_motion or default_root_motion(args.target, corr.target_roles["Hips"])
    feet = "free" if args.no_plant else args.feet
    out = retarget(motion, character, name_map=name_map, feet=feet, root_motion=mode, mesh=mesh)
    groups = foot_groups_of(corr.target_roles)
    soles = character_soles(character, corr.target_roles, mesh)
    floor = sole_floor(out, soles, character, corr.target_roles)
    plants = sole_plants(out, groups, soles, floor)  # where the soles touch: the report's and events'
    report = feet_report(motion, out, character, corr, soles, floor, plants)
    if args.report:
        try:
            Path(args.report).write_text(json.dumps({"feet": feet, **report.as_dict()}, indent=1) + "\n")
        except OSError as exc:
            raise MotionError(f"cannot write {args.report}: {exc.strerror or exc}") from None
    notes: list[str] = []
    if glb_out:
        events = contact_events(out, feet=groups, plants=plants) if kinds else None
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
        extra = contact_events(out, feet=groups, plants=plants) if kinds else None
        notes = save_motion(
            out,
            args.out,
            units=out.units if keep else None,
            events=kinds if not extra else (),  # no contact found: as any file (.bvh refuses events)
            extra_events=extra or (),
        )
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
            f"{rig_label(corr.source_preset)} {height_m(motion):.2f} m -> "
            f"{rig_label(corr.target_preset)} {height_m(character):.2f} m, "
            f"units {out.units}; root motion {mode}"
            + ("" if mode == "none" else f" on {root!r}")
            + f"; {time.perf_counter() - t0:.2f} s)"
        )
        print(f"feet ({feet}): {report.summary()}")
    return 0


RIG_LABELS = {
    "humanoid": "Unity/Godot humanoid rig",
    "mixamo": "Mixamo rig",
    "unreal": "Unreal mannequin",
    "bandai-namco": "Bandai-Namco rig",
    "cmu-daz": "CMU-Daz rig",
    "cmu": "CMU rig (LeftHip/LeftKnee names)",
    "cmu-asf": "CMU ASF rig",
    "cmu-cgspeed": "CMU rig (cgspeed BVH conversion)",
    "iclone": "iClone/Character Creator rig",
    "map": "rig named by --map",
}
"""How retarget's summary names the naming presets of :mod:`motion.retarget.names`."""


def rig_label(preset: str) -> str:
    """A naming preset as retarget's summary says it (the preset name when it has no label)."""
    return RIG_LABELS.get(preset, preset)


def cmd_samples(args: argparse.Namespace) -> int:
    from motion.samples import SAMPLES, sample_path

    for name in SAMPLES:
        print(f"{SAMPLE_PREFIX}{name}\t{sample_path(name)}")
    return 0
