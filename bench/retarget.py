"""Benchmark: retargeting (motion.retarget) onto characters of every naming preset and scale.

Real clips (needs ../shared/data; falls back to the bundled samples): CMU salsa, CMU-Daz walks,
CMU 131 start-walk-stop, iClone CMU walks, Bandai-Namco walks. Characters: a skeleton of each
convention in its first (standing) frame, hips over the origin, scaled by 0.8, 1.0 and 1.2 —
Bandai-Namco's skeleton renamed to Mixamo, Unreal and Unity/Godot humanoid names, and the CMU-Daz,
CMU and iClone skeletons of other subjects as they are. Per (preset, scale, clip), measured on the
output against the source:

* ``limb_deg``: mean angle between the source's and the output's thigh, shin, upper arm and
  forearm directions (world frame);
* ``slide_m_s``: mean horizontal speed of the output's ankles and toes on the frames where they are
  planted (contacts detected on the output), and ``source_slide_m_s`` the same on the source
  (its ankles), metres per second;
* ``sink_cm``: how far the lowest foot joint goes under its usual floor (1st percentile of the
  lowest foot joint's height minus its minimum), centimetres;
* ``root_path_ratio``: the output hips' horizontal path over the source's times the hip-height
  ratio (median height of the hips above the ankles, output over source);
* ``ms``: wall time of one retarget.

Prints one JSON object: every row and, per preset, the mean and worst of each figure.
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

from motion import Motion, Skeleton  # noqa: E402
from motion.contacts import detect_contacts  # noqa: E402
from motion.io import load_motion  # noqa: E402
from motion.retarget import PRESETS, correspond, detect_roles, retarget  # noqa: E402

DATA = ROOT.parent / "shared" / "data"
CLIPS = (
    ("cmu-salsa/60_02_scaled.bvh", 0),
    ("cmu-salsa/61_05_scaled.bvh", 0),
    ("cmu-daz/walks/02_01.bvh", 1),
    ("cmu-daz/walks/07_09.bvh", 1),
    ("cmu-start-walk-stop/131_01.bvh", 0),
    ("cmu-walks/007_02.bvh", 1),
    ("bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh", 0),
    ("bandai-namco/dataset-2/dataset-2_walk-turn-left_normal_001.bvh", 0),
)
SAMPLE_CLIPS = (("sample:salsa-leader-02", 0), ("sample:walk", 1), ("sample:start-walk-stop", 0))
BANDAI_BASE = "bandai-namco/dataset-2/dataset-2_walk_normal_002.bvh"
BASES = {  # preset -> (skeleton file, first frame, rename from Bandai-Namco names)
    "mixamo": (BANDAI_BASE, 0, True),
    "unreal": (BANDAI_BASE, 0, True),
    "humanoid": (BANDAI_BASE, 0, True),
    "bandai-namco": (BANDAI_BASE, 0, False),
    "cmu-daz": ("cmu-daz/walks/05_01.bvh", 1, False),
    "cmu": ("cmu-start-walk-stop/131_02.bvh", 0, False),
    "iclone": ("cmu-walks/007_03.bvh", 1, False),
}
SAMPLE_BASES = {"cmu-daz": ("sample:walk-10-04", 0, False), "cmu": ("sample:start-walk-stop", 0, False)}
LIMBS = (
    ("LeftUpperLeg", "LeftLowerLeg"), ("LeftLowerLeg", "LeftFoot"),
    ("RightUpperLeg", "RightLowerLeg"), ("RightLowerLeg", "RightFoot"),
    ("LeftUpperArm", "LeftLowerArm"), ("LeftLowerArm", "LeftHand"),
    ("RightUpperArm", "RightLowerArm"), ("RightLowerArm", "RightHand"),
)  # fmt: skip
FOOT = ("LeftFoot", "LeftToes", "RightFoot", "RightToes")


def _path(name: str) -> str:
    return name if name.startswith("sample:") else str(DATA / name)


def make_character(preset: str, base: tuple[str, int, bool], scale: float) -> Motion:
    """The base skeleton's standing frame, renamed to ``preset`` when asked, lengths x ``scale``."""
    path, frame, rename = base
    m = load_motion(_path(path)).slice(frame, frame + 1)
    m = m.scaled(scale)
    sk = m.skeleton
    names = list(sk.names)
    if rename:
        by_role = PRESETS["bandai-namco"]
        new = {by_role[r]: PRESETS[preset][r] for r in PRESETS[preset] if r in by_role}
        names = [new.get(n, n) for n in names]
    renamed = Skeleton(
        tuple(names), sk.parents, sk.offsets, sk.channels, sk.end_site_parents, sk.end_site_offsets
    )
    root = np.array(m.root_positions, copy=True)
    root[:, [0, 2]] = 0.0
    jt = np.array(m.joint_translations, copy=True)
    hips = detect_roles(renamed).joints["Hips"]
    slots = {int(j): k for k, j in enumerate(sk.translated_joints)}
    if hips in slots:
        jt[:, slots[hips], [0, 2]] = 0.0
    return replace(m, skeleton=renamed, root_positions=root, joint_translations=jt, name=f"{preset}-x{scale}")


def _drop(p: np.ndarray, roles: dict[str, int]) -> float:
    ankles = 0.5 * (p[:, roles["LeftFoot"], 1] + p[:, roles["RightFoot"], 1])
    return float(np.median(p[:, roles["Hips"], 1] - ankles))


def _path_len(p: np.ndarray, hips: int) -> float:
    return float(np.linalg.norm(np.diff(p[:, hips][:, [0, 2]], axis=0), axis=1).sum())


def _slide(m: Motion, pos: np.ndarray, joints: list[int]) -> float:
    idx, flags = detect_contacts(m, np.array(joints), positions=pos)
    v = np.linalg.norm(np.diff(pos[:, idx][:, :, [0, 2]], axis=0), axis=-1) * m.fps * m.metres_per_unit
    planted = flags[1:] & flags[:-1]
    return float(v[planted].mean()) if planted.any() else 0.0


def measure(src: Motion, char: Motion) -> dict[str, Any]:
    t0 = time.perf_counter()
    out = retarget(src, char)
    ms = (time.perf_counter() - t0) * 1e3
    corr = correspond(src.skeleton, char.skeleton)
    sr, tr = corr.source_roles, corr.target_roles
    ps, po = src.global_positions(), out.global_positions()
    angles = []
    for a, b in LIMBS:
        u, w = ps[:, sr[b]] - ps[:, sr[a]], po[:, tr[b]] - po[:, tr[a]]
        cos = np.sum(u * w, axis=1) / np.linalg.norm(u, axis=1) / np.linalg.norm(w, axis=1)
        angles.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).mean())
    feet_o = [tr[r] for r in FOOT if r in tr]
    lowest = po[:, feet_o, 1].min(axis=1) * out.metres_per_unit
    ratio = _drop(po, tr) * out.metres_per_unit / (_drop(ps, sr) * src.metres_per_unit)
    path_ratio = (_path_len(po, tr["Hips"]) * out.metres_per_unit) / max(
        _path_len(ps, sr["Hips"]) * src.metres_per_unit * ratio, 1e-12
    )
    return {
        "limb_deg": round(float(np.mean(angles)), 3),
        "slide_m_s": round(_slide(out, po, feet_o), 4),
        "source_slide_m_s": round(_slide(src, ps, [sr["LeftFoot"], sr["RightFoot"]]), 4),
        "sink_cm": round(float(np.percentile(lowest, 1) - lowest.min()) * 100, 3),
        "root_path_ratio": round(path_ratio, 4),
        "ms": round(ms, 1),
        "frames": src.num_frames,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=2400, help="frames per clip at most (default 2400)")
    ap.add_argument("--scales", default="0.8,1.0,1.2")
    args = ap.parse_args()
    shared = DATA.is_dir()
    clips = CLIPS if shared else SAMPLE_CLIPS
    bases = BASES if shared else SAMPLE_BASES
    sources = {name: load_motion(_path(name)).slice(start, start + args.frames) for name, start in clips}
    rows: list[dict[str, Any]] = []
    for preset, base in bases.items():
        for scale in (float(s) for s in args.scales.split(",")):
            char = make_character(preset, base, scale)
            for name, src in sources.items():
                rows.append({"preset": preset, "scale": scale, "clip": Path(name).name} | measure(src, char))
    keys = ("limb_deg", "slide_m_s", "source_slide_m_s", "sink_cm", "root_path_ratio", "ms")
    summary = {}
    for preset in bases:
        mine = [r for r in rows if r["preset"] == preset]
        summary[preset] = {k: {"mean": round(float(np.mean([r[k] for r in mine])), 4)} for k in keys}
        for k in keys:
            vals = [r[k] for r in mine]
            worst = max(vals, key=lambda v: abs(v - 1.0)) if k == "root_path_ratio" else max(vals)
            summary[preset][k]["worst"] = worst
    print(json.dumps({"data": "shared" if shared else "samples", "summary": summary, "rows": rows}))


if __name__ == "__main__":
    main()
