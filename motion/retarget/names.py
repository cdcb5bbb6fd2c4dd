"""Joint correspondence between two skeletons: naming presets, chains and an explicit name map.

Every skeleton is described by *roles*, the bone names of Unity's Humanoid avatar and Godot's
``SkeletonProfileHumanoid`` (``Hips``, ``Head``, ``LeftUpperArm``, ``RightFoot``, ...). A preset
names the joint that plays each role in one naming convention (CMU, CMU-Daz, Bandai-Namco, Mixamo,
the Unreal mannequin, Unity/Godot humanoid, iClone/Character Creator); the preset that matches
most of a skeleton's joints is used. Namespaces (``mixamorig:``, ``mixamorig1:``) are ignored.

Spine and neck joints are matched by structure, not by name, because their number differs between
conventions (CMU-Daz: abdomen, chest; Mixamo: Spine, Spine1, Spine2; Unreal 5: spine_01..05): the
torso chain runs from the hips to the joint where the arms and the neck branch (the chest), the
neck chain from there to the head. The first and last joints of the two chains correspond, joints
between them are paired by their position along the chain, and joints left over (the longer
chain's) are unmapped: they keep their rest rotation.

An explicit map ``{source joint or role: character joint}`` extends or overrides the presets.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

from ..errors import MotionError
from ..mirror import mirror_map
from ..skeleton import Skeleton

LIMBS = ("Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes")
ROLES = ("Hips", "Head", *(f"{side}{limb}" for side in ("Left", "Right") for limb in LIMBS))
REQUIRED = ("Hips", "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "RightUpperLeg", "RightLowerLeg", "RightFoot")
"""Roles both skeletons must have: the root motion and the leg IK need them."""


def _preset(hips: str, head: str, limbs: tuple[str, ...], left: str, right: str) -> dict[str, str]:
    """Role -> joint name; ``limbs`` follow :data:`LIMBS` with ``{s}`` for the side token."""
    out = {"Hips": hips, "Head": head}
    for side, token in (("Left", left), ("Right", right)):
        for limb, pattern in zip(LIMBS, limbs, strict=True):
            if pattern:
                out[f"{side}{limb}"] = pattern.format(s=token)
    return out


PRESETS: dict[str, dict[str, str]] = {
    "humanoid": _preset(
        "Hips",
        "Head",
        (
            "{s}Shoulder",
            "{s}UpperArm",
            "{s}LowerArm",
            "{s}Hand",
            "{s}UpperLeg",
            "{s}LowerLeg",
            "{s}Foot",
            "{s}Toes",
        ),
        "Left",
        "Right",
    ),
    "mixamo": _preset(
        "Hips",
        "Head",
        ("{s}Shoulder", "{s}Arm", "{s}ForeArm", "{s}Hand", "{s}UpLeg", "{s}Leg", "{s}Foot", "{s}ToeBase"),
        "Left",
        "Right",
    ),
    "unreal": _preset(
        "pelvis",
        "head",
        (
            "clavicle_{s}",
            "upperarm_{s}",
            "lowerarm_{s}",
            "hand_{s}",
            "thigh_{s}",
            "calf_{s}",
            "foot_{s}",
            "ball_{s}",
        ),
        "l",
        "r",
    ),
    "bandai-namco": _preset(
        "Hips",
        "Head",
        (
            "Shoulder_{s}",
            "UpperArm_{s}",
            "LowerArm_{s}",
            "Hand_{s}",
            "UpperLeg_{s}",
            "LowerLeg_{s}",
            "Foot_{s}",
            "Toes_{s}",
        ),
        "L",
        "R",
    ),
    "cmu-daz": _preset(
        "hip",
        "head",
        ("{s}Collar", "{s}Shldr", "{s}ForeArm", "{s}Hand", "{s}Thigh", "{s}Shin", "{s}Foot", "{s}Toe"),
        "l",
        "r",
    ),
    "cmu": _preset(
        "Hips",
        "Head",
        ("{s}Collar", "{s}Shoulder", "{s}Elbow", "{s}Wrist", "{s}Hip", "{s}Knee", "{s}Ankle", "{s}Toe"),
        "Left",
        "Right",
    ),
    "cmu-asf": _preset(
        "root",
        "head",
        ("{s}clavicle", "{s}humerus", "{s}radius", "{s}wrist", "{s}femur", "{s}tibia", "{s}foot", "{s}toes"),
        "l",
        "r",
    ),
    "iclone": _preset(
        "CC_Base_Hip",
        "CC_Base_Head",
        (
            "CC_Base_{s}_Clavicle",
            "CC_Base_{s}_Upperarm",
            "CC_Base_{s}_Forearm",
            "CC_Base_{s}_Hand",
            "CC_Base_{s}_Thigh",
            "CC_Base_{s}_Calf",
            "CC_Base_{s}_Foot",
            "CC_Base_{s}_ToeBase",
        ),
        "L",
        "R",
    ),
}
"""Naming conventions: ``humanoid`` is Unity's Humanoid and Godot's humanoid profile; ``cmu`` the
CMU BVH conversions with ``LeftHip/LeftKnee/LeftAnkle``; ``cmu-asf`` the ASF bone names."""

_NAMESPACE = re.compile(r"^.*[:|]")


def bare_name(name: str) -> str:
    """A joint name without a namespace prefix (``mixamorig:Hips`` -> ``Hips``)."""
    return _NAMESPACE.sub("", name)


def role_label(role: str) -> str:
    """A role for messages: ``LeftUpperLeg`` -> ``left upper leg``."""
    return re.sub(r"(?<!^)([A-Z])", r" \1", role).lower()


@dataclass(frozen=True)
class Roles:
    """The roles found on one skeleton: ``preset`` (best matching convention, ``""`` when none
    matched) and ``joints`` role -> joint index."""

    preset: str
    joints: dict[str, int]


def detect_roles(skeleton: Skeleton) -> Roles:
    """The roles of a skeleton's joints under the preset that matches most of them (ties: the
    order of :data:`PRESETS`). Exact names first, then case-insensitive unique ones."""
    bare = [bare_name(n) for n in skeleton.names]
    exact = {n: i for i, n in enumerate(bare)}
    lower: dict[str, list[int]] = {}
    for i, n in enumerate(bare):
        lower.setdefault(n.lower(), []).append(i)
    best = Roles("", {})
    for preset, table in PRESETS.items():
        found: dict[str, int] = {}
        for role, name in table.items():
            if name in exact:
                found[role] = exact[name]
            elif len(lower.get(name.lower(), [])) == 1:
                found[role] = lower[name.lower()][0]
        score = (sum(r in found for r in REQUIRED), len(found))
        if score > (sum(r in best.joints for r in REQUIRED), len(best.joints)):
            best = Roles(preset, found)
    return best


@dataclass(frozen=True)
class Correspondence:
    """Which source joint drives which character joint.

    Attributes
    ----------
    pairs:
        character joint index -> source joint index.
    target_roles, source_roles:
        role -> joint index on each side (roles present on both sides are paired).
    target_preset, source_preset:
        the naming conventions recognised (``"map"`` when only the explicit map named the roles).
    """

    pairs: dict[int, int]
    target_roles: dict[str, int]
    source_roles: dict[str, int]
    target_preset: str
    source_preset: str

    def side(self, skeleton: Skeleton) -> dict[int, int]:
        """Character joint -> +1 left, -1 right, 0 centre (roles first, then names)."""
        _, by_name = mirror_map(skeleton.names)
        out = {j: int(by_name[j]) for j in self.pairs}
        for role, j in self.target_roles.items():
            out[j] = 1 if role.startswith("Left") else -1 if role.startswith("Right") else 0
        return out


def _ancestors(skeleton: Skeleton, joint: int) -> list[int]:
    """``joint`` and its ancestors up to the root, nearest first."""
    out = [joint]
    while skeleton.parents[out[-1]] >= 0:
        out.append(int(skeleton.parents[out[-1]]))
    return out


def _path_between(skeleton: Skeleton, top: int, bottom: int) -> list[int] | None:
    """Joints strictly below ``bottom`` down to ``top`` inclusive, in hierarchy order; None when
    ``top`` is not below ``bottom``."""
    chain = _ancestors(skeleton, top)
    if bottom not in chain[1:]:
        return None
    return chain[: chain.index(bottom)][::-1]


def _branch_point(skeleton: Skeleton, joints: list[int]) -> int:
    """The deepest common ancestor of ``joints`` (the chest for the two arms and the head)."""
    common = set(_ancestors(skeleton, joints[0]))
    for j in joints[1:]:
        common &= set(_ancestors(skeleton, j))
    return max(common, key=lambda j: len(_ancestors(skeleton, j)))


def torso_chain(skeleton: Skeleton, roles: dict[str, int]) -> tuple[list[int], list[int]]:
    """Torso chain (above the hips up to the chest, inclusive) and neck chain (above the chest,
    below the head) of a skeleton with hips, head and both arms; empty lists when unknown."""
    arms = [roles.get(f"{s}Shoulder", roles.get(f"{s}UpperArm", -1)) for s in ("Left", "Right")]
    if "Hips" not in roles or "Head" not in roles or min(arms) < 0:
        return [], []
    chest = _branch_point(skeleton, [*arms, roles["Head"]])
    torso = _path_between(skeleton, chest, roles["Hips"]) or []
    neck = _path_between(skeleton, roles["Head"], chest) or []
    return torso, neck[:-1]


def pair_chains(target: list[int], source: list[int]) -> dict[int, int]:
    """Pair two chains of joints: first with first, last with last, the others by their fraction
    along the chain (each source joint used once); leftovers stay unpaired."""
    if not target or not source:
        return {}
    out = {target[0]: source[0], target[-1]: source[-1]}
    used = {source[0], source[-1]}
    m, n = len(target), len(source)
    for i in range(1, m - 1):
        k = round(i / (m - 1) * (n - 1))
        if 0 < k < n - 1 and source[k] not in used:
            out[target[i]] = source[k]
            used.add(source[k])
    return out


def correspond(
    source: Skeleton, target: Skeleton, name_map: Mapping[str, str] | None = None
) -> Correspondence:
    """The joint correspondence from ``source`` (the motion) to ``target`` (the character).

    ``name_map`` maps a source joint name, or a role (:data:`ROLES`), to a character joint name;
    it adds to and overrides the presets. Raises :class:`MotionError` naming the missing required
    roles (hips, legs, feet) or a map entry naming no joint.
    """
    src, tgt = detect_roles(source), detect_roles(target)
    src_roles, tgt_roles = dict(src.joints), dict(tgt.joints)
    extra: dict[int, int] = {}
    t_index = {n: i for i, n in enumerate(target.names)}
    s_index = {n: i for i, n in enumerate(source.names)}
    role_of_source = {j: r for r, j in src_roles.items()}
    for key, value in (name_map or {}).items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise MotionError("the joint map must map names (strings) to names")
        if value not in t_index:
            raise MotionError(f"joint map: the character has no joint named {value!r}")
        if key in s_index:
            role = role_of_source.get(s_index[key])
            if role is None:
                extra[t_index[value]] = s_index[key]
            else:
                tgt_roles[role] = t_index[value]
        elif key in ROLES:
            if key not in src_roles:
                raise MotionError(f"joint map: the motion has no joint for the role {key!r}")
            tgt_roles[key] = t_index[value]
        else:
            raise MotionError(
                f"joint map: {key!r} is neither a joint of the motion nor a role ({', '.join(ROLES)})"
            )
    for who, roles, sk in (("motion", src_roles, source), ("character", tgt_roles, target)):
        missing = [r for r in REQUIRED if r not in roles]
        if missing:
            preset = (src if who == "motion" else tgt).preset or "none"
            raise MotionError(
                f"the {who} has no joint for: {', '.join(role_label(r) for r in missing)} (naming convention "
                f"recognised: {preset}; known: {', '.join(PRESETS)}; joints: {', '.join(sk.names[:8])}"
                f"{', ...' if sk.num_joints > 8 else ''}); name them with a joint map (--map)"
            )
    pairs = {tgt_roles[r]: src_roles[r] for r in ROLES if r in tgt_roles and r in src_roles}
    t_torso, t_neck = torso_chain(target, tgt_roles)
    s_torso, s_neck = torso_chain(source, src_roles)
    for t, s in (*pair_chains(t_torso, s_torso).items(), *pair_chains(t_neck, s_neck).items()):
        pairs.setdefault(t, s)
    pairs.update(extra)
    return Correspondence(pairs, tgt_roles, src_roles, tgt.preset or "map", src.preset or "map")
