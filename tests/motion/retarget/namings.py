"""One skinned character under three namings: Unreal's, Mixamo's and names of its own (no preset
knows them, no name says foot, toe or ankle), with the role map that names its joints.

A test character is built in Unreal names (:mod:`tests.motion.retarget.gltf_rig`, or any GLB whose
skin uses them); :func:`renamed_glb` renames its nodes (the file is otherwise byte-for-byte the
same skeleton, skin and mesh), so the three characters differ in their names only.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np

from motion import Motion, Skeleton
from motion import rotations as rot
from motion.io import load_motion
from motion.skeleton import default_channels

NAMINGS = ("unreal", "mixamo", "own")

BANDAI_WALK = (
    Path(__file__).resolve().parents[4] / "shared/data/bandai-namco/dataset-2/dataset-2_walk_normal_002.bvh"
)
"""A Bandai-Namco clip whose first frame is :func:`bandai_rig` (``../shared/data``)."""

_SIDES = {"l": ("Left", "L"), "r": ("Right", "R")}


def _side_table(side: str) -> dict[str, dict[str, str]]:
    word, letter = _SIDES[side]
    return {
        f"clavicle_{side}": {"mixamo": f"mixamorig:{word}Shoulder", "own": f"{letter}_collar"},
        f"upperarm_{side}": {"mixamo": f"mixamorig:{word}Arm", "own": f"{letter}_brachium"},
        f"lowerarm_{side}": {"mixamo": f"mixamorig:{word}ForeArm", "own": f"{letter}_antebrachium"},
        f"hand_{side}": {"mixamo": f"mixamorig:{word}Hand", "own": f"{letter}_manus"},
        f"thigh_{side}": {"mixamo": f"mixamorig:{word}UpLeg", "own": f"{letter}_femur_jnt"},
        f"calf_{side}": {"mixamo": f"mixamorig:{word}Leg", "own": f"{letter}_crus"},
        f"foot_{side}": {"mixamo": f"mixamorig:{word}Foot", "own": f"{letter}_pes"},
        f"ball_{side}": {"mixamo": f"mixamorig:{word}ToeBase", "own": f"{letter}_digiti"},
    }


_TABLE: dict[str, dict[str, str]] = {
    "root": {"mixamo": "Armature_root", "own": "base"},
    "pelvis": {"mixamo": "mixamorig:Hips", "own": "sacrum"},
    "spine_01": {"mixamo": "mixamorig:Spine", "own": "lumbar"},
    "spine_02": {"mixamo": "mixamorig:Spine1", "own": "thorax_a"},
    "spine_03": {"mixamo": "mixamorig:Spine2", "own": "thorax_b"},
    "neck_01": {"mixamo": "mixamorig:Neck", "own": "cervix"},
    "head": {"mixamo": "mixamorig:Head", "own": "cranium"},
    "ik_foot_root": {"mixamo": "ik_helper", "own": "ik_helper"},
    **_side_table("l"),
    **_side_table("r"),
}

ROLE_OF_UNREAL = {
    "pelvis": "Hips", "head": "Head",
    **{f"{u}_{s}": f"{_SIDES[s][0]}{role}" for s in "lr" for u, role in (
        ("clavicle", "Shoulder"), ("upperarm", "UpperArm"), ("lowerarm", "LowerArm"), ("hand", "Hand"),
        ("thigh", "UpperLeg"), ("calf", "LowerLeg"), ("foot", "Foot"), ("ball", "Toes"),
    )},
}  # fmt: skip
"""Unreal joint -> its role (:data:`motion.retarget.names.ROLES`)."""


def name_in(naming: str, unreal: str) -> str:
    """The joint called ``unreal`` in Unreal's naming, in ``naming``'s."""
    if naming == "unreal":
        return unreal
    return _TABLE.get(unreal, {}).get(naming, f"{naming}_{unreal}" if naming == "own" else unreal)


def role_map(naming: str = "own", *, toes: bool = True) -> dict[str, str]:
    """``{role: joint}`` naming every role of the character in ``naming`` (its toes unless
    ``toes`` is false), as a user writes for ``--map``."""
    return {
        role: name_in(naming, unreal)
        for unreal, role in ROLE_OF_UNREAL.items()
        if toes or not role.endswith("Toes")
    }


def renamed_glb(raw: bytes, naming: str, rename: Callable[[str], str] | None = None) -> bytes:
    """A GLB in Unreal names with its joints renamed to ``naming`` (:data:`NAMINGS`), or any GLB
    with each joint ``n`` renamed to ``rename(n)``."""
    if rename is None:
        if naming == "unreal":
            return raw
        rename = lambda n: name_in(naming, n)  # noqa: E731
    n = struct.unpack_from("<I", raw, 12)[0]
    doc = json.loads(raw[20 : 20 + n])
    joints = {int(j) for skin in doc.get("skins", []) for j in skin["joints"]}
    for i, node in enumerate(doc["nodes"]):
        if i in joints and "name" in node:
            node["name"] = rename(node["name"])
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = raw[20 + n :]
    total = 12 + 8 + len(text) + len(rest)
    return b"".join(
        (struct.pack("<4sII", b"glTF", 2, total), struct.pack("<II", len(text), 0x4E4F534A), text, rest)
    )


def game_rig(root: bool = True) -> Motion:
    """The skeleton of :mod:`tests.motion.retarget.gltf_rig` (Unreal names, a root at the floor, a
    ball joint per foot, End Sites at the head's, hands' and toes' tips) as a one-frame motion in
    metres, standing in its rest pose (zero rotations: legs down, arms out). ``root=False``: the
    skeleton starts at its hips (as Mixamo's does), without ``root`` and ``ik_foot_root``."""
    from .gltf_rig import JOINTS

    joints = [j for j in JOINTS if root or j[0] not in ("root", "ik_foot_root")]
    names = tuple(j[0] for j in joints)
    pos = np.array([j[2] for j in joints])
    parents = np.array([names.index(p) if p in names else -1 for _, p, _ in joints], dtype=np.intp)
    offsets = np.array([pos[k] - (pos[p] if p >= 0 else 0.0) for k, p in enumerate(parents)])
    from .gltf_rig import TIPS

    tips = [(names.index(n), np.array(t) - pos[names.index(n)]) for n, t in TIPS.items()]
    skeleton = Skeleton(
        names,
        parents,
        offsets,
        default_channels(len(names)),
        np.array([k for k, _ in tips], dtype=np.intp),
        np.array([o for _, o in tips]),
    )
    q = np.tile(rot.IDENTITY, (1, len(names), 1))
    return Motion(skeleton, offsets[:1].copy(), q, 30.0, units="m", name="game_rig")


BANDAI_UNREAL = {
    "Hips": "pelvis", "Spine": "spine_01", "Chest": "spine_02", "Neck": "neck_01", "Head": "head",
    "Shoulder_L": "clavicle_l", "UpperArm_L": "upperarm_l", "LowerArm_L": "lowerarm_l", "Hand_L": "hand_l",
    "Shoulder_R": "clavicle_r", "UpperArm_R": "upperarm_r", "LowerArm_R": "lowerarm_r", "Hand_R": "hand_r",
    "UpperLeg_L": "thigh_l", "LowerLeg_L": "calf_l", "Foot_L": "foot_l", "Toes_L": "ball_l",
    "UpperLeg_R": "thigh_r", "LowerLeg_R": "calf_r", "Foot_R": "foot_r", "Toes_R": "ball_r",
}  # fmt: skip


def bandai_rig() -> Motion:
    """Bandai-Namco's skeleton in Unreal names, its first frame (metres): a rest pose from a clip."""
    m = load_motion(BANDAI_WALK).slice(0, 1)
    m = m.to_units("m")
    sk = m.skeleton
    names = tuple(BANDAI_UNREAL.get(n, n) for n in sk.names)
    renamed = Skeleton(names, sk.parents, sk.offsets, sk.channels, sk.end_site_parents, sk.end_site_offsets)
    root = np.array(m.root_positions, copy=True)
    root[:, [0, 2]] = 0.0
    return Motion(renamed, root, m.rotations, m.fps, m.joint_translations, m.units, "bandai_rig")


def mannequin_character(naming: str = "unreal", rest: Motion | None = None) -> bytes:
    """A skinned character GLB: Segue's mannequin (:func:`motion.export.mannequin.mannequin_glb`:
    smooth weights, a heel behind the ankle, a ball and toes, soles flat on the rest floor) on
    ``rest`` (default :func:`game_rig`, in Unreal names), its joints named after ``naming``."""
    from motion.export.mannequin import mannequin_glb

    rest = game_rig() if rest is None else rest
    names = [name_in(naming, n) for n in rest.skeleton.names]
    return mannequin_glb(rest, names=names)
