"""The ``segue`` command line.

Commands::

    segue inspect FILE [--json] [--units U]       frames, fps, joints, height and units guess
    segue convert IN OUT [--fps N] [--target T]   BVH -> .bvh/.bvh.gz/.glb/.json/.npz
    segue samples                                 list the bundled sample clips
    segue demo [--out DIR]                        inspect + convert a bundled sample

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

from motion import Motion, MotionError
from motion.allocator import tune_allocator
from motion.bvh import BvhLimits, detect_units
from motion.export.targets import TARGETS
from motion.ground import add_ground_root
from motion.io import OUTPUT_SUFFIXES, load_motion, save_motion
from motion.resample import resample
from motion.samples import SAMPLES, sample_path
from motion.units import METRES_PER_UNIT

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
    for name, kwargs in (("salsa-leader.glb", {}), ("salsa-leader.json", {}), ("salsa-leader.npz", {})):
        t0 = time.perf_counter()
        save_motion(motion, out / name, **kwargs)
        size_mb = (out / name).stat().st_size / 1e6
        print(f"  wrote {out / name} ({size_mb:.1f} MB, {time.perf_counter() - t0:.2f} s)")
    print("open the .glb in any glTF viewer (e.g. https://gltf-viewer.donmccurdy.com) to watch it dance")
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="segue", description="Segue: motion synthesis by example from motion capture."
    )
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def limits(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--max-joints", type=int, default=1024, help="refuse files with more joints (default 1024)"
        )
        p.add_argument("--max-frames", type=int, default=2_000_000, help="refuse files with more frames")

    units = sorted(METRES_PER_UNIT)
    p = sub.add_parser("inspect", help="frames, fps, joints, height and units guess of a BVH file")
    p.add_argument("file", help="BVH file (.bvh, .bvh.gz) or sample:NAME")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--units", choices=units, help="declare the file's length unit instead of guessing")
    limits(p)
    p.set_defaults(func=cmd_inspect)

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
    limits(p)
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser("samples", help="list the bundled sample clips")
    p.set_defaults(func=cmd_samples)

    p = sub.add_parser("demo", help="inspect a bundled salsa clip and convert it to GLB, JSON and NPZ")
    p.add_argument("--out", default="segue-demo", help="output directory (default ./segue-demo)")
    p.set_defaults(func=cmd_demo)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    tune_allocator()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except MotionError as exc:
        print(f"segue: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"segue: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
