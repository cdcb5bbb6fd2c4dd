"""Which bone of an artist's armature plays each part of the body (hips, legs, feet, arms, head).

Segue recognises a character's joints by naming conventions (Mixamo, Unreal, Unity humanoid...);
an artist's rig may follow none. So the add-on finds the roles itself, from the skeleton's shape
in its rest pose (and from words in the bone names where they are unambiguous), shows them in the
panel for the artist to correct, and uploads the rig with those bones renamed to Unity/Godot
humanoid names (:data:`ROLES`; :func:`upload_names`), which Segue recognises; every other bone
keeps its own name. Results come back with the same names and are keyed on the artist's bones.

Input positions are world space, metres, Blender's axes (Z up); the character may face any way
(its facing is read from its feet: toes point forward).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from .mat4 import Vec3

LIMBS = ("Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes")
ROLES = ("Hips", "Head", *(f"{side}{limb}" for side in ("Left", "Right") for limb in LIMBS))
"""Unity's Humanoid / Godot's humanoid profile names: what the uploaded rig's role bones are called."""
REQUIRED = ("Hips", "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "RightUpperLeg", "RightLowerLeg", "RightFoot")
"""Roles Segue needs to put a motion on a character (root motion and leg IK)."""


@dataclass(frozen=True, slots=True)
class Bone:
    """A bone in the rest pose: its name, parent's name, head and tail (world, metres, Z up)."""

    name: str
    parent: str | None
    head: Vec3
    tail: Vec3


class RoleError(ValueError):
    """Roles that cannot be used (a missing required role, a bone named twice)."""


def _sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _dot(a: Vec3, b: Vec3) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _norm(a: Vec3) -> float:
    return float(_dot(a, a) ** 0.5)


def _unit(a: Vec3) -> Vec3:
    n = _norm(a) or 1.0
    return (a[0] / n, a[1] / n, a[2] / n)


_WORDS: dict[str, tuple[str, ...]] = {  # limb -> words of a bone name that say it, unambiguously
    "Shoulder": ("clavicle", "collar", "shoulder"),
    "UpperArm": ("upperarm", "upper_arm", "humerus", "uparm", "uparm"),
    "LowerArm": ("forearm", "lowerarm", "lower_arm", "elbow", "radius", "ulna"),
    "Hand": ("hand", "wrist"),
    "UpperLeg": ("thigh", "upperleg", "upper_leg", "upleg", "femur"),
    "LowerLeg": ("shin", "calf", "knee", "lowerleg", "lower_leg", "tibia"),
    "Foot": ("foot", "ankle"),
    "Toes": ("toe", "ball"),
}


def _says(name: str, limb: str) -> bool:
    low = re.sub(r"[^a-z_]", "", name.lower().replace(".", "_"))
    flat = low.replace("_", "")
    words = _WORDS[limb]
    if limb == "Shoulder" and any(w in flat for w in ("upperarm", "upper_arm")):
        return False
    if limb == "Hand" and any(w in flat for w in ("finger", "thumb", "index", "pinky", "ring", "middle")):
        return False
    if limb == "Foot" and "toe" in flat:
        return False
    return any(w.replace("_", "") in flat for w in words)


class _Skeleton:
    def __init__(self, bones: Sequence[Bone]) -> None:
        self.bones = {b.name: b for b in bones}
        if len(self.bones) != len(bones):
            raise RoleError("two bones share a name")
        self.children: dict[str | None, list[str]] = {}
        for b in bones:
            parent = b.parent if b.parent in self.bones else None
            self.children.setdefault(parent, []).append(b.name)
        zs = [p[2] for b in bones for p in (b.head, b.tail)]
        self.floor, self.top = min(zs), max(zs)
        self.height = max(self.top - self.floor, 1e-9)
        self._sub: dict[str, list[str]] = {}

    def subtree(self, name: str) -> list[str]:
        if name not in self._sub:
            out = [name]
            for c in self.children.get(name, []):
                out += self.subtree(c)
            self._sub[name] = out
        return self._sub[name]

    def points(self, name: str) -> list[Vec3]:
        return [p for n in self.subtree(name) for p in (self.bones[n].head, self.bones[n].tail)]

    def low(self, name: str) -> float:
        return min(p[2] for p in self.points(name))

    def ancestors(self, name: str) -> list[str]:
        out = []
        p = self.bones[name].parent
        while p is not None and p in self.bones:
            out.append(p)
            p = self.bones[p].parent
        return out

    def length(self, name: str) -> float:
        b = self.bones[name]
        return _norm(_sub(b.tail, b.head))

    def chain(self, start: str, key: Callable[[list[Vec3]], float]) -> list[str]:
        """From ``start`` down, at each bone the child whose subtree minimizes ``key(points)``."""
        out = [start]
        while kids := self.children.get(out[-1]):
            out.append(min(kids, key=lambda c: key(self.points(c))))
        return out


def detect_roles(bones: Sequence[Bone], forward_hint: Vec3 = (0.0, -1.0, 0.0)) -> dict[str, str]:
    """Role -> bone name for the roles found (:data:`ROLES`); required ones missing are left out
    (:func:`missing_roles` names them).

    The hips are the bone where the two legs (the subtrees reaching the floor) meet; in each leg
    the foot is the first bone pointing forward rather than down near the floor, the lower leg
    the bone whose head (the knee) is nearest half way between the hip joint and the ankle; the
    character's left is ``up x forward`` (forward: the feet's direction, else ``forward_hint``,
    Blender's -Y). The spine climbs from the hips to the highest point; the head is its last bone
    starting below the top 5%; the arms are the two subtrees off the spine reaching farthest to
    each side, the hand their first bone that branches into fingers (or a short last bone).
    Where bone names say a limb part unambiguously (``forearm``, ``shin``, ``clavicle``...),
    the first bone of the chain that says it wins over the shape."""
    sk = _Skeleton(bones)
    if not bones:
        return {}
    roles: dict[str, str] = {}
    near_floor = sk.floor + 0.12 * sk.height
    # the legs: children subtrees of the hips reaching near the floor
    low_leaves = [n for n in sk.bones if not sk.children.get(n) and sk.low(n) < near_floor]
    if len(low_leaves) < 2:
        low_leaves = [n for n in sk.bones if sk.low(n) < near_floor]
    hips = None
    for n in sorted(sk.bones, key=lambda n: -len(sk.ancestors(n))):  # deepest first
        kids = [c for c in sk.children.get(n, []) if sk.low(c) < near_floor]
        if len(kids) >= 2:
            hips = n
            break
    if hips is None:
        return roles
    roles["Hips"] = hips
    hip_head = sk.bones[hips].head
    legs = sorted((c for c in sk.children[hips] if sk.low(c) < near_floor), key=sk.low)[:2]
    leg_chains = [sk.chain(c, lambda pts: min(p[2] for p in pts)) for c in legs]
    feet = [_foot(sk, ch) for ch in leg_chains]
    fwd = (0.0, 0.0, 0.0)
    for ch, f in zip(leg_chains, feet, strict=True):
        if f is not None:
            b = sk.bones[ch[f]]
            d = _sub(b.tail, b.head)
            fwd = (fwd[0] + d[0], fwd[1] + d[1], 0.0)
    if _norm(fwd) < 1e-6:
        fwd = (forward_hint[0], forward_hint[1], 0.0)
    fwd = _unit(fwd)
    left = (-fwd[1], fwd[0], 0.0)  # up (0, 0, 1) x forward
    for ch, f in zip(leg_chains, feet, strict=True):
        if f is None:
            continue
        side = "Left" if _dot(_sub(sk.bones[ch[f]].head, hip_head), left) > 0 else "Right"
        roles.update({f"{side}{k}": v for k, v in _leg_roles(sk, ch, f).items()})
    # the spine and the head: up from the hips towards the highest point
    others = [c for c in sk.children.get(hips, []) if c not in legs]
    if others:
        top = max(others, key=lambda c: max(p[2] for p in sk.points(c)))
        spine = [hips, *sk.chain(top, lambda pts: -max(p[2] for p in pts))]
    else:
        spine = [hips]
    head_limit = sk.top - 0.05 * sk.height
    heads = [n for n in spine[1:] if sk.bones[n].head[2] < head_limit and sk.length(n) > 0.02 * sk.height]
    if heads:
        roles["Head"] = heads[-1]
    # the arms: off the spine, farthest to each side
    on_spine = set(spine)
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        best, reach = None, 0.15 * sk.height
        for s in spine:
            for c in sk.children.get(s, []):
                if c in on_spine or c in legs:
                    continue
                r = max(sign * _dot(_sub(p, hip_head), left) for p in sk.points(c))
                if r > reach:
                    best, reach = c, r
        if best is not None:

            def outward(pts: list[Vec3], sg: float = sign) -> float:
                return -max(sg * _dot(_sub(p, hip_head), left) for p in pts)

            arm = sk.chain(best, outward)
            roles.update({f"{side}{k}": v for k, v in _arm_roles(sk, arm).items()})
    return roles


def _foot(sk: _Skeleton, chain: list[str]) -> int | None:
    """Index in a leg chain of the foot: named so, else the first bone near the floor pointing
    more forward than down (else the last bone starting in the lowest quarter)."""
    named = [i for i, n in enumerate(chain) if i > 0 and _says(n, "Foot")]
    if named:
        return named[0]
    quarter = sk.floor + 0.25 * sk.height
    for i, n in enumerate(chain):
        b = sk.bones[n]
        d = _unit(_sub(b.tail, b.head))
        if i > 0 and b.head[2] < quarter and abs(d[2]) < 0.75:
            return i
    low = [i for i, n in enumerate(chain) if i > 0 and sk.bones[n].head[2] < quarter]
    return low[-1] if low else None


def _leg_roles(sk: _Skeleton, chain: list[str], f: int) -> dict[str, str]:
    out = {"Foot": chain[f]}
    if f + 1 < len(chain):
        out["Toes"] = chain[f + 1]
    above = chain[:f]
    if not above:
        return out
    down = [n for n in above if _unit(_sub(sk.bones[n].tail, sk.bones[n].head))[2] < -0.5] or above
    named_upper = [n for n in down if _says(n, "UpperLeg")]
    upper = named_upper[0] if named_upper else down[0]
    out["UpperLeg"] = upper
    between = above[above.index(upper) + 1 :]
    named_lower = [n for n in between if _says(n, "LowerLeg")]
    if named_lower:
        out["LowerLeg"] = named_lower[0]
    elif between:
        hip_z, ankle_z = sk.bones[upper].head[2], sk.bones[chain[f]].head[2]
        mid = 0.5 * (hip_z + ankle_z)
        out["LowerLeg"] = min(between, key=lambda n: abs(sk.bones[n].head[2] - mid))
    return out


def _arm_roles(sk: _Skeleton, chain: list[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    named = {
        limb: [n for n in chain if _says(n, limb)] for limb in ("Shoulder", "UpperArm", "LowerArm", "Hand")
    }
    # the hand: named, else the first bone branching into fingers, else a short last bone
    hand = named["Hand"][0] if named["Hand"] else None
    if hand is None:
        for n in chain[1:]:
            kids = [
                c
                for c in sk.children.get(n, [])
                if len(sk.subtree(c)) > 1 or sk.length(c) >= 0.25 * sk.length(n)
            ]
            if len(kids) >= 2:
                hand = n
                break
        if hand is None and len(chain) >= 3 and sk.length(chain[-1]) < 0.6 * sk.length(chain[-2]):
            hand = chain[-1]
    if hand is None:
        return out
    out["Hand"] = hand
    before = chain[: chain.index(hand)]
    if not before:
        return out
    first = sk.bones[before[0]]
    clavicle = len(before) >= 3 and sk.length(before[0]) < 0.75 * sk.length(before[1])
    if named["Shoulder"] and named["Shoulder"][0] in before:
        out["Shoulder"] = named["Shoulder"][0]
    elif clavicle and abs(first.head[0] - first.tail[0]) + abs(first.head[1] - first.tail[1]) > 0:
        out["Shoulder"] = before[0]
    rest = before[before.index(out["Shoulder"]) + 1 :] if "Shoulder" in out else before
    if not rest:
        return out
    upper = next((n for n in rest if _says(n, "UpperArm")), rest[0])
    out["UpperArm"] = upper
    between = rest[rest.index(upper) + 1 :]
    lower = next((n for n in between if _says(n, "LowerArm")), None)
    if lower is None and between:
        s, w = sk.bones[upper].head, sk.bones[hand].head
        mid = ((s[0] + w[0]) / 2, (s[1] + w[1]) / 2, (s[2] + w[2]) / 2)
        lower = min(between, key=lambda n: _norm(_sub(sk.bones[n].head, mid)))
    if lower is not None:
        out["LowerArm"] = lower
    return out


def missing_roles(roles: Mapping[str, str]) -> list[str]:
    """The required roles (:data:`REQUIRED`) not given."""
    return [r for r in REQUIRED if not roles.get(r)]


def upload_names(bone_names: Sequence[str], roles: Mapping[str, str]) -> dict[str, str]:
    """Bone name -> the name it is uploaded under: each role's bone gets the role's name; a bone
    whose own name is a role name (any case) but plays another part gets ``_`` appended (until
    unique), so that Segue never mistakes it; others keep their names. ``RoleError`` when a bone
    plays two roles or a role names no bone of the list."""
    names = set(bone_names)
    by_bone: dict[str, str] = {}
    for role, bone in roles.items():
        if role not in ROLES:
            raise RoleError(f"{role!r} is not a role ({', '.join(ROLES)})")
        if not bone:
            continue
        if bone not in names:
            raise RoleError(f"role {role}: the armature has no bone {bone!r}")
        if bone in by_bone:
            raise RoleError(f"bone {bone!r} plays two roles: {by_bone[bone]} and {role}")
        by_bone[bone] = role
    reserved = {r.lower() for r in ROLES}
    out: dict[str, str] = {}
    used: set[str] = set(by_bone.values())
    for n in bone_names:
        if n in by_bone:
            out[n] = by_bone[n]
            continue
        new = n
        while new.lower() in reserved or (new != n and (new in names or new in used)):
            new += "_"
        out[n] = new
        used.add(new)
    return out
