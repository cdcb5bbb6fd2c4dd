"""Benchmark: GLB size of crowds, one skin per character (motion/export/glb.py, issue 15).

A crowd result holds every dancer in one combined motion (a static ``world`` root, ``cN_`` joint
names; :mod:`motion.export.characters`); its GLB gives each dancer its own skin. This builds crowds
of ``--dancers`` salsa dancers from the bundled 30 fps salsa samples (each dancer a ``--seconds``
window of one of the 9 bundled leader/follower clips, from its own start frame, standing on its own
spot of a 1.5 m grid: different motions, like a rhythm crowd's) and prints one JSON object:

- ``crowds``: per crowd size, the GLB ``bytes`` (and ``MB``), ``bytes_per_dancer``, the number of
  skins and meshes, and the export time ``export_s`` (``glb_bytes``; includes the ground root of
  each dancer);
- ``per_dancer_growth``: ``(bytes(largest) - bytes(smallest)) / (dancers(largest) - dancers(smallest))``
  and ``linear``: whether each size's bytes are within 1% of the line through the smallest and the
  largest crowds.

The engines' crowds write the same layout, so a rhythm crowd of the same length, fps and skeleton
has these sizes. Run: ``python bench/glb_size.py [--dancers 1,40,500] [--seconds 20]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from motion.export.characters import combine_characters  # noqa: E402
from motion.export.glb import glb_bytes  # noqa: E402
from motion.io import load_motion  # noqa: E402
from motion.motion import Motion  # noqa: E402

CLIPS = [f"sample:salsa-{role}-{n}" for n in ("02", "04", "05") for role in ("leader", "follower")] + [
    "sample:salsa-leader-12"
]


def crowd(n: int, frames: int, clips: list[Motion]) -> Motion:
    """``n`` dancers of ``frames`` frames: dancer ``k`` dances clip ``k % len(clips)`` from start
    frame ``(7 k) % (clip frames - frames)``, moved to its grid spot (1.5 m apart)."""
    side = int(np.ceil(np.sqrt(n)))
    people: list[Motion] = []
    for k in range(n):
        clip = clips[k % len(clips)]
        start = (7 * k) % max(clip.num_frames - frames, 1)
        m = clip.slice(start, start + frames)
        spot = np.array([1.5 * (k % side), 0.0, 1.5 * (k // side)]) / m.metres_per_unit
        people.append(replace(m, root_positions=m.root_positions + spot))
    return combine_characters(people, [f"c{k}_" for k in range(n)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dancers", default="1,40,500", help="crowd sizes, comma-separated")
    ap.add_argument("--seconds", type=float, default=12.0, help="crowd length in seconds (30 fps)")
    args = ap.parse_args()
    sizes = sorted({int(s) for s in args.dancers.split(",")})
    clips = [load_motion(c) for c in CLIPS]
    fps = clips[0].fps
    frames = int(round(args.seconds * fps))
    shortest = min(c.num_frames for c in clips)
    if frames > shortest:
        raise SystemExit(f"--seconds {args.seconds}: the bundled clips have {shortest / fps:.1f} s at most")
    rows: list[dict[str, Any]] = []
    for n in sizes:
        m = crowd(n, frames, clips)
        t = time.perf_counter()
        data = glb_bytes(m)
        took = time.perf_counter() - t
        head = json.loads(data[20 : 20 + int.from_bytes(data[12:16], "little")])
        rows.append(
            {
                "dancers": n,
                "frames": frames,
                "fps": fps,
                "joints_per_dancer": clips[0].num_joints,
                "bytes": len(data),
                "MB": round(len(data) / 1e6, 2),
                "bytes_per_dancer": round(len(data) / n),
                "skins": len(head["skins"]),
                "meshes": len(head.get("meshes", [])),
                "export_s": round(took, 3),
            }
        )
        del m, data
    first, last = rows[0], rows[-1]
    growth = (last["bytes"] - first["bytes"]) / max(last["dancers"] - first["dancers"], 1)
    linear = all(
        abs(r["bytes"] - (first["bytes"] + growth * (r["dancers"] - first["dancers"]))) <= 0.01 * r["bytes"]
        for r in rows
    )
    print(json.dumps({"crowds": rows, "per_dancer_growth": round(growth), "linear": linear}, indent=1))


if __name__ == "__main__":
    main()
