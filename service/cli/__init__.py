"""The ``segue`` command line.

Commands::

    segue inspect FILE [--json] [--units U] [--up A]  frames, fps, joints, height, units, up axis (BVH, GLB)
    segue inspect DIR [--json]                    a database segue build wrote: its summary (clips,
                                                  labels, skeleton; what a graph build left out)
    segue beats FILE [--json] [--joints A,B] [--positions] [--tempo LO:HI]   motion beats (Kim et al. 2003)
    segue beats SONG.wav [--json] [--tempo-bpm X]      music beats of a recording (WAV, FLAC, Ogg, MP3)
    segue convert IN OUT [--fps N] [--target T] [--feet lock|grounding|free]
                                                  BVH -> .bvh/.bvh.gz/.glb/.json/.npz
    segue retarget MOTION --to CHARACTER --out OUT [--map MAP.json] [--rest first|zero]
           [--target T] [--root-motion root|hips|none] [--animation-only] [--events contacts]
           [--feet lock|grounding|free] [--report FEET.json]
                                                  the motion on another character (BVH or GLB/glTF skin;
                                                  a GLB character's own file with the animation added)
    segue samples                                 list the bundled samples (clips and a MIDI song)
    segue demo [--out DIR]                        convert a bundled clip and dance it (rhythm)
    segue demo ENGINE [--out DIR]                 one engine end to end on bundled clips (service.demos)
    segue build SPEC.json --out DIR               build a database (same JSON as POST /v1/databases)
    segue synth REQUEST.json --db DIR --out OUT [--feet lock|grounding|free]
                                                  run a job in-process (same JSON as POST /v1/jobs)
    segue graph DIR [--json]                      a rhythm database's movement transition graph
    segue graph-edit DIR EDITS.json --out DIR2    derive a database with an edited movement graph
    segue serve [--host H] [--port P] [--redis URL] [--import DIR]   the HTTP/WebSocket API (+ embedded
                                                  workers), serving database folders segue build wrote
    segue worker --redis URL                      a Redis job worker
    segue blender-addon --out FILE.zip            the Blender add-on, as a zip Blender installs

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
from collections.abc import Sequence

from .addon import cmd_blender_addon
from .demo import cmd_demo
from .files import (
    DEFAULT_MAX_JOINT_FRAMES,
    FEET_MODES,
    OUTPUT_SUFFIXES,
    SAMPLE_PREFIX,
    TARGETS,
    UNITS,
    cmd_beats,
    cmd_convert,
    cmd_inspect,
    cmd_retarget,
    cmd_samples,
)
from .jobs import _validation_message, cmd_build, cmd_graph, cmd_graph_edit, cmd_synth
from .serve import cmd_serve, cmd_warm, cmd_worker

__all__ = ["FEET_MODES", "OUTPUT_SUFFIXES", "SAMPLE_PREFIX", "TARGETS", "UNITS", "build_parser", "main"]


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

    def feet_option(p: argparse.ArgumentParser, default: str | None, what: str = "") -> None:
        p.add_argument(
            "--feet",
            choices=FEET_MODES,
            default=default,
            help="lock: planted feet held in place, soles on the floor; grounding: soles on the floor "
            f"only (no sole under it, planted soles on it); free: feet left as they are{what}"
            + (f" (default {default})" if default else ""),
        )

    def limits(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--max-joints", type=int, default=1024, help="refuse files with more joints (default 1024)"
        )
        p.add_argument("--max-frames", type=int, default=2_000_000, help="refuse files with more frames")
        p.add_argument(
            "--max-joint-frames",
            type=int,
            default=DEFAULT_MAX_JOINT_FRAMES,
            help=f"refuse files with more frames x joints (default {DEFAULT_MAX_JOINT_FRAMES:,})",
        )

    def animation(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--animation",
            metavar="NAME|INDEX",
            help="which animation of a glTF/GLB file (default: its first; segue inspect lists them)",
        )

    from ..demos import DEMOS

    units = sorted(UNITS)
    p = command(
        "inspect",
        help="frames, fps, joints, height, units and up axis of a BVH or glTF/GLB file; "
        "the summary of a database folder segue build wrote",
    )
    p.add_argument(
        "file", help="BVH file (.bvh, .bvh.gz), glTF file (.glb, .gltf), sample:NAME, or a database folder"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--units", choices=units, help="declare the file's length unit instead of guessing")
    p.add_argument(
        "--up",
        choices=("auto", "y", "z"),
        default="auto",
        help="the file's vertical axis, for the height (default: detected; Segue's Unreal BVH is Z up)",
    )
    animation(p)
    limits(p)
    p.set_defaults(func=cmd_inspect)

    p = command(
        "beats",
        help="motion beats of a BVH file (Kim et al. 2003) or music beats of a recording (WAV FLAC Ogg MP3)",
    )
    p.add_argument(
        "file",
        help="BVH (.bvh, .bvh.gz) or glTF (.glb, .gltf) file, sample:NAME, or a .wav/.flac/.ogg/.mp3 "
        "recording",
    )
    animation(p)
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

    p = command(
        "convert", help="convert a BVH or glTF/GLB motion by output extension: " + " ".join(OUTPUT_SUFFIXES)
    )
    p.add_argument(
        "input", help="BVH file (.bvh, .bvh.gz), glTF file with an animation (.glb, .gltf) or sample:NAME"
    )
    animation(p)
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
    feet_option(p, "free", "; the motion's own feet, soles from its bones")
    reference_options(p)
    p.add_argument("--quiet", "-q", action="store_true", help="print nothing on success")
    limits(p)
    p.set_defaults(func=cmd_convert)

    p = command("retarget", help="put a motion on another character (BVH or GLB/glTF skin)")
    p.add_argument(
        "motion",
        help="the motion: BVH file (.bvh, .bvh.gz), glTF file with an animation (.glb, .gltf) or sample:NAME",
    )
    animation(p)
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
    feet_option(p, "lock")
    p.add_argument("--no-plant", action="store_true", help=argparse.SUPPRESS)  # before --feet free
    p.add_argument("--report", help="write the feet's figures (motion.retarget.report) to this JSON file")
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
    feet_option(p, None, "; overrides the request's feet (graph, annotations, control, rhythm)")
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
    p.add_argument(
        "--data",
        help="this worker's local directory (default $SEGUE_DATA_DIR or ./segue-data): its cache of "
        "databases when $SEGUE_STORE_URL names an object store, else the store itself (then the same "
        "directory as the API's)",
    )
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

    p = command(
        "blender-addon",
        help="write the Blender add-on as a zip that Blender 4.2+ installs (docs/blender.md)",
        description="Write the Blender add-on (integrations/blender) as a zip: Blender 4.2+ installs it "
        "as an extension (Get Extensions > Install from Disk) or as a legacy add-on "
        "(Add-ons > Install from Disk).",
    )
    p.add_argument("--out", required=True, help="the zip to write, e.g. segue_blender.zip")
    p.set_defaults(func=cmd_blender_addon)
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
