"""Test characters: the bundled CMU-Daz walk's skeleton renamed into other naming conventions,
rescaled and reproportioned, in its first (reference) pose; and limb-direction measures."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from motion import Motion, Skeleton
from motion.io import load_motion

Array = npt.NDArray[np.float64]

_DAZ_CENTRE = ("hip", "abdomen", "chest", "neck", "head")
_DAZ_SIDE = ("Collar", "Shldr", "ForeArm", "Hand", "Buttock", "Thigh", "Shin", "Foot")


def _table(centre: tuple[str, ...], side: tuple[str, ...], left: str, right: str) -> dict[str, str]:
    out = dict(zip(_DAZ_CENTRE, centre, strict=True))
    for daz_side, token in (("l", left), ("r", right)):
        for part, name in zip(_DAZ_SIDE, side, strict=True):
            out[daz_side + part] = name.format(s=token)
    return out


# CMU-Daz joint -> the same joint in each convention (written out here, independently of the
# presets in motion.retarget.names; "Buttock" joints get names no preset knows)
RENAMES: dict[str, dict[str, str]] = {
    "mixamo": _table(
        ("mixamorig:Hips", "mixamorig:Spine", "mixamorig:Spine1", "mixamorig:Neck", "mixamorig:Head"),
        (
            "mixamorig:{s}Shoulder", "mixamorig:{s}Arm", "mixamorig:{s}ForeArm", "mixamorig:{s}Hand",
            "mixamorig:{s}HipBone", "mixamorig:{s}UpLeg", "mixamorig:{s}Leg", "mixamorig:{s}Foot",
        ),
        "Left", "Right",
    ),
    "unreal": _table(
        ("pelvis", "spine_01", "spine_02", "neck_01", "head"),
        (
            "clavicle_{s}", "upperarm_{s}", "lowerarm_{s}", "hand_{s}",
            "hipjoint_{s}", "thigh_{s}", "calf_{s}", "foot_{s}",
        ),
        "l", "r",
    ),
    "humanoid": _table(
        ("Hips", "Spine", "Chest", "Neck", "Head"),
        (
            "{s}Shoulder", "{s}UpperArm", "{s}LowerArm", "{s}Hand",
            "{s}HipJoint", "{s}UpperLeg", "{s}LowerLeg", "{s}Foot",
        ),
        "Left", "Right",
    ),
    "bandai-namco": _table(
        ("Hips", "Spine", "Chest", "Neck", "Head"),
        (
            "Shoulder_{s}", "UpperArm_{s}", "LowerArm_{s}", "Hand_{s}",
            "Hip_{s}", "UpperLeg_{s}", "LowerLeg_{s}", "Foot_{s}",
        ),
        "L", "R",
    ),
    "cmu": _table(
        ("Hips", "lowerback", "Chest", "Neck", "Head"),
        ("{s}Collar", "{s}Shoulder", "{s}Elbow", "{s}Wrist", "{s}HipJoint", "{s}Hip", "{s}Knee", "{s}Ankle"),
        "Left", "Right",
    ),
    "iclone": _table(
        ("CC_Base_Hip", "CC_Base_Waist", "CC_Base_Spine01", "CC_Base_NeckTwist01", "CC_Base_Head"),
        (
            "CC_Base_{s}_Clavicle", "CC_Base_{s}_Upperarm", "CC_Base_{s}_Forearm", "CC_Base_{s}_Hand",
            "CC_Base_{s}_Pelvis", "CC_Base_{s}_Thigh", "CC_Base_{s}_Calf", "CC_Base_{s}_Foot",
        ),
        "L", "R",
    ),
}  # fmt: skip

# (joint, child) of the limbs compared, in CMU-Daz names
LIMBS = (
    ("lThigh", "lShin"), ("lShin", "lFoot"), ("rThigh", "rShin"), ("rShin", "rFoot"),
    ("lShldr", "lForeArm"), ("lForeArm", "lHand"), ("rShldr", "rForeArm"), ("rForeArm", "rHand"),
)  # fmt: skip


def walk(frames: int = 240) -> Motion:
    """The bundled CMU-Daz walk (cm), from frame 1 (frame 0 is its reference pose)."""
    return load_motion("sample:walk").slice(1, 1 + frames)


def character(
    convention: str | None = None,
    *,
    scale: float = 1.0,
    shin: float = 1.0,
    source: str = "sample:walk-10-04",
) -> Motion:
    """A one-frame character: ``source``'s first frame, joints renamed to ``convention`` (CMU-Daz
    names when None), every length times ``scale`` and the shins times ``shin``, its hips moved
    over the origin."""
    m = load_motion(source).slice(0, 1).scaled(scale)
    sk = m.skeleton
    names = list(sk.names)
    if convention is not None:
        table = RENAMES[convention]
        names = [table.get(n, n) for n in names]
    offsets = np.array(sk.offsets, copy=True)
    for j, n in enumerate(sk.names):
        if n in ("lFoot", "rFoot"):
            offsets[j] *= shin
    renamed = Skeleton(
        tuple(names), sk.parents, offsets, sk.channels, sk.end_site_parents, sk.end_site_offsets
    )
    root = np.array(m.root_positions, copy=True)
    root[:, [0, 2]] = 0.0
    return replace(m, skeleton=renamed, root_positions=root, name=convention or "cmu-daz")


def bone_directions(m: Motion, pairs: tuple[tuple[str, str], ...]) -> Array:
    """``(F, P, 3)`` unit vectors from each joint to its child, world frame."""
    pos = m.global_positions()
    idx = {n: i for i, n in enumerate(m.skeleton.names)}
    v = np.stack([pos[:, idx[b]] - pos[:, idx[a]] for a, b in pairs], axis=1)
    return np.asarray(v / np.linalg.norm(v, axis=-1, keepdims=True))


def angle_deg(u: Array, v: Array) -> Array:
    """Angles in degrees between unit vectors ``u`` and ``v`` (same shapes)."""
    return np.asarray(np.degrees(np.arccos(np.clip(np.sum(u * v, axis=-1), -1.0, 1.0))))


def renamed_limbs(convention: str | None) -> tuple[tuple[str, str], ...]:
    """:data:`LIMBS` in ``convention``'s names."""
    if convention is None:
        return LIMBS
    t = RENAMES[convention]
    return tuple((t[a], t[b]) for a, b in LIMBS)
