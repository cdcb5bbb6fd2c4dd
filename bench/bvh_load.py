"""Benchmark: BVH parse + forward kinematics, and the reader's peak memory.

Prints one JSON object: ``{"file", "frames", "joints", "parse_s", "fk_s", "joint_frames_per_s",
"parse_peak_mib", "text_mib", "hostile"}`` where the times are medians over ``--runs`` runs,
``joint_frames_per_s = frames * joints / (parse_s + fk_s)``, ``parse_peak_mib`` is the peak of
Python and numpy allocations (``tracemalloc``) while one read of the file's bytes parses them
(``text_mib`` of BVH text after gunzip), and ``hostile`` the same for a gzip file whose header
declares ``--hostile-frames`` frames of the file's skeleton and that holds them (issue 40.3:
``{"frames", "gzip_mib", "text_mib", "peak_mib", "s", "outcome"}``; refused at the header by
the joint-frame limit of ``--max-joint-frames``, as the service's ``SEGUE_MAX_JOINT_FRAMES``).
Default file: the bundled CMU salsa leader sample (or ``--file``). Runs with the allocator tuning
every Segue process applies (``motion.allocator``).
"""

from __future__ import annotations

import argparse
import gzip
import json
import statistics
import sys
import time
import tracemalloc
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from motion import BvhError, BvhLimits, parse_bvh, read_bvh
from motion.allocator import tune_process
from motion.samples import sample_path


def _peak_read(data: bytes, limits: BvhLimits | None = None) -> tuple[float, float, str]:
    """Peak traced MiB and seconds of one parse of ``data``, and its outcome."""
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        outcome = f"read {parse_bvh(data, limits=limits).num_frames} frames"
    except BvhError as exc:
        outcome = f"refused: {exc.problem}"
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return round(peak / 2**20, 1), round(seconds, 3), outcome


def _hostile(text: bytes, frames: int, max_joint_frames: int) -> dict[str, Any]:
    """A gzip file declaring and holding ``frames`` copies of the first frame line of ``text``:
    the header one gzip member, then one member of 1,000 rows repeated (a valid multi-member gzip,
    made in milliseconds whatever ``frames``)."""
    head, _, rows = text.partition(b"MOTION")
    first_row = rows.split(b"\n")[3] + b"\n"
    block = 1000
    header = head + b"MOTION\nFrames: %d\nFrame Time: 0.008333\n" % frames
    packed = gzip.compress(header, 9) + gzip.compress(first_row * block, 9) * (frames // block)
    packed += gzip.compress(first_row * (frames % block), 9) if frames % block else b""
    limits = BvhLimits(max_frames=frames, max_bytes=1 << 40, max_joint_frames=max_joint_frames)
    peak, seconds, outcome = _peak_read(packed, limits)
    return {
        "frames": frames,
        "gzip_mib": round(len(packed) / 2**20, 2),
        "text_mib": round((len(header) + len(first_row) * frames) / 2**20, 1),
        "peak_mib": peak,
        "s": seconds,
        "outcome": outcome,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--file", help="BVH file (.bvh or .bvh.gz); default: bundled salsa leader")
    ap.add_argument("--runs", type=int, default=31, help="timed runs (median reported)")
    ap.add_argument(
        "--hostile-frames", type=int, default=1_900_000, help="frames of the hostile gzip (0: skip)"
    )
    ap.add_argument(
        "--max-joint-frames", type=int, default=10_000_000, help="the limit the hostile file meets"
    )
    args = ap.parse_args(argv)
    tune_process()  # as in every Segue process (see motion/allocator.py)
    path = Path(args.file) if args.file else sample_path("salsa-leader")
    read_bvh(path).global_positions()  # warm caches (imports, page cache)
    parse_t, fk_t = [], []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        motion = read_bvh(path, units="m")
        t1 = time.perf_counter()
        motion.global_positions()
        t2 = time.perf_counter()
        parse_t.append(t1 - t0)
        fk_t.append(t2 - t1)
    parse_s, fk_s = statistics.median(parse_t), statistics.median(fk_t)
    raw = path.read_bytes()
    text = gzip.decompress(raw) if raw[:2] == b"\x1f\x8b" else raw
    peak, _, _ = _peak_read(raw)
    out = {
        "file": str(path),
        "frames": motion.num_frames,
        "joints": motion.num_joints,
        "parse_s": round(parse_s, 6),
        "fk_s": round(fk_s, 6),
        "joint_frames_per_s": round(motion.num_frames * motion.num_joints / (parse_s + fk_s)),
        "parse_peak_mib": peak,
        "text_mib": round(len(text) / 2**20, 2),
    }
    if args.hostile_frames:
        out["hostile"] = _hostile(text, args.hostile_frames, args.max_joint_frames)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
