"""A skinned body for any skeleton, made from its rest pose alone: the geometry of Segue's mannequin.

Animators judge motion on a body, not on lines: feet through the floor, hands through hips and
arm swing show on a surface. Segue has no character of its own to ship (no outside assets), so it
makes one from the skeleton it is given, in the way a wooden artist's mannequin is made: a smooth
shape per body part, each skinned to its bones with weights that blend across the joints.

Parts (found by the skeleton's roles, :func:`motion.retarget.names.detect_roles`, in the rest
pose, sized by its standing height ``H``; figures below for ``H = 1.75 m``)
    * **torso**: an elliptic loft along the spine chain (hips to chest,
      :func:`~motion.retarget.names.torso_chain`) from below the hip joints to the shoulders,
      half-widths 0.17 m at the pelvis, 0.13 m at the waist, 0.16 m at the chest; each ring
      weighted to the two spine joints whose bones' midpoints bracket it;
    * **neck** and **head** (an ellipsoid from the head joint to the head's tip);
    * **limbs**: tapered capsules from joint to joint (thigh 8 to 5 cm radius, shin 5 to 3.3 cm,
      upper arm 4.6 to 3.6 cm, forearm 3.6 to 2.6 cm, collar bone 4.5 cm), weighted to the bone's
      own joint and blending half-and-half into the neighbouring bones at the joints;
    * **hands**: a flattened capsule from the wrist to the finger tips (the hand's farthest
      descendant or End Site; a hand length along the forearm when it has none);
    * **feet**: a foot with a **flat sole on the rest floor** (the lowest joint or End Site of the
      rest pose): a rounded heel 0.3 of the ankle-to-toe distance behind the ankle, a ball at the
      toe joint, toes to the toe tip; heel to ball weighted to the foot joint, blending into the
      toe joint across the ball. The sole is what touches the floor, as on a real character.

A skeleton whose roles are not found (no hips, legs, feet, head or arms under any naming
convention) gets a tapered capsule along every bone instead, sized by its body length.

Shapes are generated, not sculpted: a mannequin, not a likeness. The sizes are those of an adult
(standing height ``H``), scaled with ``H``; joint positions are the skeleton's own, so proportions
(leg length, shoulder width) follow the rig.

Written by hand: glTF writers (trimesh, pygltflib) need a mesh to write, and what is made here is
the mesh — a skin of rigged parts whose weights follow the skeleton's roles — which no library
makes for an arbitrary skeleton.

:mod:`motion.export.mannequin` makes it for a motion's pose and writes it as a character GLB;
:func:`motion.export.glb.glb_bytes` draws any export with it (``mesh="body"``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..retarget.names import detect_roles, torso_chain
from ..skeleton import Skeleton

Array = npt.NDArray[np.float64]

__all__ = ["SkinnedMesh", "body_mesh"]

REFERENCE_HEIGHT_M = 1.75  # the figures of the module docstring are for this standing height
AROUND = 18  # vertices around each ring
INFLUENCES = 4  # glTF's JOINTS_0 / WEIGHTS_0

# radii (m at the reference height) at the top and bottom of each limb bone
LIMB_RADII: dict[str, tuple[float, float]] = {
    "UpperLeg": (0.088, 0.056),
    "LowerLeg": (0.054, 0.035),
    "Shoulder": (0.045, 0.045),
    "UpperArm": (0.046, 0.036),
    "LowerArm": (0.036, 0.026),
}
# the torso: (fraction from below the hips to the shoulders, half-width, half-depth), m
TORSO_PROFILE = (
    (0.00, 0.150, 0.095),
    (0.12, 0.170, 0.105),
    (0.30, 0.150, 0.095),
    (0.48, 0.130, 0.088),
    (0.70, 0.155, 0.105),
    (0.88, 0.165, 0.100),
    (1.00, 0.120, 0.070),
)
NECK_RADIUS = 0.048
HEAD_SEMI_AXES = (0.078, 0.112, 0.095)  # lateral, vertical, depth (m)
HEAD_HEIGHT = 0.2  # from the head joint (the skull's base) to the top of the head (m)
HAND_HALF_WIDTH, HAND_HALF_THICKNESS = 0.045, 0.018
# the foot, from the heel (u = 0) to the toe tip (u = 1): (u, half-width, height of its top) in m;
# ``None`` height at the ankle means "just above the ankle joint"
HEEL_BACK = 0.3  # the heel, behind the ankle, as a fraction of the ankle-to-toe-tip distance
FOOT_PROFILE = ((0.0, 0.030, 0.060), (0.12, 0.034, 0.075), (0.62, 0.047, 0.050), (1.0, 0.036, 0.024))
ANKLE_TOP_ABOVE_JOINT = 0.035
SOLE_SQUARENESS = 0.35  # the sole's superellipse exponent (< 1: a flat, square-edged sole)
SOLE_FLATNESS = 1.25  # > 1: the lowest vertices of each ring lie on the floor (a flat sole)


@dataclass(frozen=True, slots=True)
class SkinnedMesh:
    """A triangle mesh bound to a skeleton's joints.

    Attributes
    ----------
    positions:
        ``(V, 3)`` vertices in the rest pose, metres, Y up (the frame the rest positions were in).
    normals:
        ``(V, 3)`` unit vertex normals (smooth within each part).
    joints:
        ``(V, 4)`` joint indices (``uint16``; index = the skeleton's joint index).
    weights:
        ``(V, 4)`` skin weights (``float32``), each row summing to 1, unused slots 0.
    indices:
        ``(T, 3)`` triangles (``uint32``), counter-clockwise seen from outside.
    """

    positions: Array
    normals: Array
    joints: npt.NDArray[np.uint16]
    weights: npt.NDArray[np.float32]
    indices: npt.NDArray[np.uint32]

    @property
    def num_vertices(self) -> int:
        return int(self.positions.shape[0])


def body_mesh(
    skeleton: Skeleton,
    positions: Array,
    end_points: Array,
    *,
    skip: int = 0,
    roles: Mapping[str, int] | None = None,
) -> SkinnedMesh:
    """The mannequin of a skeleton standing in the pose given by its joint positions.

    Parameters
    ----------
    skeleton:
        The joint hierarchy (names find the roles; offsets are not used).
    positions:
        ``(J, 3)`` global joint positions of the pose, metres, Y up, the body facing +Z or not.
    end_points:
        ``(E, 3)`` End Site positions (``skeleton.end_site_parents``), metres.
    skip:
        Joints ``0 .. skip-1`` (a ground root above the hips) carry no part.
    roles:
        Role -> joint index (:data:`motion.retarget.names.ROLES`) when the caller knows them;
        found from the names otherwise.

    Returns
    -------
    The skinned body (module docstring). The floor is the lowest joint or End Site below the
    hips.
    """
    positions = np.asarray(positions, dtype=np.float64)
    end_points = np.asarray(end_points, dtype=np.float64).reshape(-1, 3)
    found = dict(detect_roles(skeleton).joints if roles is None else roles)
    body = _Body(skeleton, positions, end_points, skip)
    needed = (
        "Hips",
        "Head",
        *(f"{s}{p}" for s in ("Left", "Right") for p in ("UpperLeg", "LowerLeg", "Foot")),
    )
    arms = all(f"{s}{p}" in found for s in ("Left", "Right") for p in ("UpperArm", "LowerArm", "Hand"))
    parts = _human(body, found) if all(r in found for r in needed) and arms else _capsules(body)
    return _merged(parts)


# ------------------------------------------------------------------------------------------------
# the body and its parts
# ------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Part:
    """One closed surface: ``(V, 3)`` vertices, ``(T, 3)`` triangles and ``(V, 4)`` joints and
    weights."""

    positions: Array
    triangles: npt.NDArray[np.intp]
    joints: npt.NDArray[np.intp]
    weights: Array


class _Body:
    """The pose the body is built on: points, floor and size."""

    def __init__(self, skeleton: Skeleton, positions: Array, end_points: Array, skip: int) -> None:
        self.skeleton = skeleton
        self.positions = positions
        self.end_points = end_points
        self.skip = skip
        body = positions[skip:]
        ends = end_points[skeleton.end_site_parents >= skip] if end_points.size else end_points
        points = np.concatenate((body, ends)) if ends.size else body
        self.floor = float(points[:, 1].min())
        self.height = max(float(points[:, 1].max()) - self.floor, 1e-6)
        self.size = max(float(np.max(points.max(axis=0) - points.min(axis=0))), 1e-6)
        self.scale = self.height / REFERENCE_HEIGHT_M

    def tip(self, joint: int) -> Array | None:
        """The farthest point below ``joint`` (a descendant joint or End Site), None for a leaf
        joint without an End Site."""
        sk = self.skeleton
        subtree = np.zeros(sk.num_joints, dtype=bool)  # the joint and its descendants
        subtree[joint] = True
        for j in range(joint + 1, sk.num_joints):  # parents come before their children
            if sk.parents[j] >= 0:
                subtree[j] = subtree[sk.parents[j]]
        ends = self.end_points[subtree[sk.end_site_parents]] if self.end_points.size else self.end_points
        points = np.concatenate((self.positions[subtree], ends.reshape(-1, 3)))
        if not len(points):
            return None
        d = np.linalg.norm(points - self.positions[joint], axis=-1)
        return None if float(d.max()) <= 1e-9 else np.asarray(points[int(np.argmax(d))])


def _human(body: _Body, roles: Mapping[str, int]) -> list[_Part]:
    """The parts of a body whose roles are known (module docstring)."""
    s = body.scale
    p = body.positions
    parts: list[_Part] = []
    left = p[roles["LeftUpperLeg"]] - p[roles["RightUpperLeg"]]
    lateral = _unit(left - left[1] * np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]))
    forward = np.cross(lateral, [0.0, 1.0, 0.0])  # left x up: the body faces +Z when its left is +X
    parts.append(_torso(body, roles, lateral, forward))
    torso, neck = torso_chain(body.skeleton, dict(roles))
    chest = torso[-1] if torso else roles["Hips"]
    head = roles["Head"]
    neck_base = neck[0] if neck else head
    top = p[neck_base] if neck else 0.5 * (p[chest] + p[head])
    parts.append(
        _capsule(top, p[head], NECK_RADIUS * s, NECK_RADIUS * s, ((neck_base, 1.0),), ((head, 1.0),))
    )
    up = _unit(p[head] - p[roles["Hips"]], np.array([0.0, 1.0, 0.0]))  # the body's up
    tip = body.tip(head)
    height = HEAD_HEIGHT * s
    if tip is not None:
        height = float(np.clip(np.dot(tip - p[head], up), 0.75 * height, 1.5 * height))
    a, b, c = HEAD_SEMI_AXES
    centre = p[head] + up * (height - b * s) + forward * 0.01 * s
    parts.append(_ellipsoid(centre, up * b * s, lateral * a * s, forward * c * s, head))
    for side in ("Left", "Right"):
        chain = [roles.get(f"{side}{limb}") for limb in ("Shoulder", "UpperArm", "LowerArm", "Hand")]
        for k, limb in ((0, "Shoulder"), (1, "UpperArm"), (2, "LowerArm")):
            own, nxt = chain[k], chain[k + 1]
            if own is None or nxt is None:
                continue
            prev = chain[k - 1] if k > 0 else None
            r0, r1 = LIMB_RADII[limb]
            parts.append(_limb(p[own], p[nxt], r0 * s, r1 * s, chest if prev is None else prev, own, nxt))
        parts.append(_hand(body, roles[f"{side}Hand"], roles[f"{side}LowerArm"], forward))
        for limb, nxt_limb in (("UpperLeg", "LowerLeg"), ("LowerLeg", "Foot")):
            own, nxt = roles[f"{side}{limb}"], roles[f"{side}{nxt_limb}"]
            before = roles["Hips"] if limb == "UpperLeg" else roles[f"{side}UpperLeg"]
            r0, r1 = LIMB_RADII[limb]
            parts.append(_limb(p[own], p[nxt], r0 * s, r1 * s, before, own, nxt))
        parts.append(_foot(body, roles[f"{side}Foot"], roles.get(f"{side}Toes"), forward))
    return parts


def _capsules(body: _Body) -> list[_Part]:
    """A tapered capsule along every bone (a skeleton whose roles are unknown)."""
    sk = body.skeleton
    p = body.positions
    parts: list[_Part] = []
    heads = [(int(sk.parents[j]), p[j], j) for j in range(1, sk.num_joints)]
    heads += [(int(e), body.end_points[k], -1) for k, e in enumerate(sk.end_site_parents)]
    for parent, tail, child in heads:
        if parent < body.skip:
            continue
        length = float(np.linalg.norm(tail - p[parent]))
        if length <= 1e-3 * body.size:
            continue
        r = min(0.035 * body.size, 0.3 * length)
        grand = int(sk.parents[parent])
        before = grand if grand >= body.skip else parent
        parts.append(_limb(p[parent], tail, r, 0.75 * r, before, parent, child if child >= 0 else parent))
    return parts


# ------------------------------------------------------------------------------------------------
# shapes
# ------------------------------------------------------------------------------------------------

Influence = tuple[tuple[int, float], ...]


def _torso(body: _Body, roles: Mapping[str, int], lateral: Array, forward: Array) -> _Part:
    """An elliptic loft from below the hip joints to the shoulders along the spine chain."""
    s = body.scale
    p = body.positions
    torso, _ = torso_chain(body.skeleton, dict(roles))
    chain = [roles["Hips"], *torso]
    hips_y = 0.5 * (p[roles["LeftUpperLeg"], 1] + p[roles["RightUpperLeg"], 1])
    shoulders = [roles.get(f"{side}UpperArm") for side in ("Left", "Right")]
    shoulder_y = float(np.mean([p[j, 1] for j in shoulders if j is not None]))
    bottom = p[chain[0]].copy()
    bottom[1] = min(hips_y, p[chain[0], 1]) - 0.05 * s
    top = p[chain[-1]].copy()
    top[1] = max(shoulder_y, p[chain[-1], 1]) + 0.03 * s
    line = np.concatenate((bottom[None], p[chain], top[None]))
    arc = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=-1))))
    total = max(float(arc[-1]), 1e-9)
    rings = 16
    f = np.linspace(0.0, 1.0, rings)
    centres = np.stack([np.interp(f * total, arc, line[:, k]) for k in range(3)], axis=-1)
    prof = np.asarray(TORSO_PROFILE)
    half_w = np.interp(f, prof[:, 0], prof[:, 1]) * s
    half_d = np.interp(f, prof[:, 0], prof[:, 2]) * s
    hip_span = 0.5 * float(np.linalg.norm(p[roles["LeftUpperLeg"]] - p[roles["RightUpperLeg"]]))
    half_w = np.maximum(
        half_w, np.interp(f, [0.0, 0.2, 0.35], [hip_span + 0.07 * s, hip_span + 0.07 * s, 0.0])
    )
    joint_arc = arc[1:-1]  # each chain joint's place along the loft
    influences = [_along_chain(chain, joint_arc, float(a)) for a in f * total]
    return _tube(centres, lateral, forward, half_w, half_d, influences, caps=(0.6, 0.5))


def _along_chain(chain: Sequence[int], at: Array, s: float) -> Influence:
    """Weights of the chain joints at arc length ``s`` (``at``: each joint's arc length): linear
    between the centres of the bones they own (a joint owns the bone up to the next joint; the
    last one the stretch above it), so that each joint's weight peaks on its own bone and blends
    into its neighbours'."""
    if len(chain) == 1:
        return ((chain[0], 1.0),)
    last = float(at[-1] - at[-2])
    centres = np.concatenate((0.5 * (at[:-1] + at[1:]), [at[-1] + 0.5 * last]))
    if s <= centres[0]:
        return ((chain[0], 1.0),)
    if s >= centres[-1]:
        return ((chain[-1], 1.0),)
    k = int(np.searchsorted(centres, s)) - 1
    w = (s - centres[k]) / max(float(centres[k + 1] - centres[k]), 1e-12)
    return ((chain[k], 1.0 - w), (chain[k + 1], w))


def _limb(a: Array, b: Array, r0: float, r1: float, before: int, own: int, after: int) -> _Part:
    """A tapered capsule from ``a`` to ``b`` owned by joint ``own``: half-and-half with the bone
    before (``before``) at ``a`` and with the next (``after``) at ``b``, fully ``own`` between."""
    return _capsule(a, b, r0, r1, ((own, 0.5), (before, 0.5)), ((own, 0.5), (after, 0.5)), own=own)


def _capsule(
    a: Array, b: Array, r0: float, r1: float, start: Influence, end: Influence, own: int | None = None
) -> _Part:
    """A tapered capsule between two points; weights blend from ``start`` (at ``a``) through
    ``own`` alone (the middle, when given) to ``end`` (at ``b``)."""
    axis = b - a
    d = _unit(axis, np.array([0.0, 1.0, 0.0]))
    u = _unit(np.cross(d, _least_parallel(d)), np.array([1.0, 0.0, 0.0]))
    v = np.cross(d, u)
    rings = 7
    t = np.linspace(0.0, 1.0, rings)
    centres = a + t[:, None] * axis
    radius = r0 + (r1 - r0) * t
    influences: list[Influence] = []
    for x in t:
        if own is None:
            influences.append(_blend(start, end, x))
        elif x < 0.3:
            influences.append(_blend(start, ((own, 1.0),), x / 0.3))
        elif x > 0.7:
            influences.append(_blend(((own, 1.0),), end, (x - 0.7) / 0.3))
        else:
            influences.append(((own, 1.0),))
    return _tube(centres, u, v, radius, radius, influences, caps=(1.0, 1.0))


def _hand(body: _Body, hand: int, forearm: int, forward: Array) -> _Part:
    """A flattened capsule from the wrist to the finger tips, weighted to the hand."""
    p = body.positions
    s = body.scale
    tip = body.tip(hand)
    along = _unit(p[hand] - p[forearm], np.array([1.0, 0.0, 0.0]))
    if tip is None or float(np.linalg.norm(tip - p[hand])) < 0.08 * s:
        tip = p[hand] + along * 0.18 * s
    d = _unit(tip - p[hand], along)
    flat = _unit(np.cross(d, forward), np.array([0.0, -1.0, 0.0]))  # the palm's normal
    width = _unit(np.cross(flat, d), np.array([0.0, 0.0, 1.0]))
    rings = 5
    t = np.linspace(0.0, 1.0, rings)
    centres = p[hand] + t[:, None] * (tip - p[hand])
    half_w = HAND_HALF_WIDTH * s * np.array([0.75, 1.0, 1.0, 0.9, 0.6])
    half_t = HAND_HALF_THICKNESS * s * np.array([1.1, 1.0, 0.9, 0.8, 0.6])
    influences: list[Influence] = [((hand, 1.0),)] * rings
    return _tube(centres, width, flat, half_w, half_t, influences, caps=(0.6, 0.8))


def _foot(body: _Body, ankle: int, toes: int | None, forward: Array) -> _Part:
    """A foot with a flat sole on the floor, from a heel behind the ankle to the toe tip."""
    p = body.positions
    s = body.scale
    a = p[ankle]
    tip = body.tip(toes if toes is not None else ankle)
    if toes is not None and tip is None:
        tip = p[toes]
    if tip is None:
        tip = a + forward * 0.19 * s
    ahead = (tip - a) * np.array([1.0, 0.0, 1.0])
    reach = float(np.linalg.norm(ahead))
    if reach < 0.05 * s:  # a tip not ahead of the ankle: the body's forward decides
        ahead, reach = forward * 0.19 * s, 0.19 * s
    f = ahead / reach
    lateral = np.cross([0.0, 1.0, 0.0], f)
    floor = body.floor
    heel = a * np.array([1.0, 0.0, 1.0]) + np.array([0.0, floor, 0.0]) - f * HEEL_BACK * reach
    length = reach * (1.0 + HEEL_BACK)
    ball_u = HEEL_BACK / (1.0 + HEEL_BACK) + 0.6 * (1.0 - HEEL_BACK / (1.0 + HEEL_BACK))
    if toes is not None:
        ball_u = float(np.clip(np.dot(p[toes] - heel, f) / length, 0.45, 0.9))
    ankle_u = HEEL_BACK / (1.0 + HEEL_BACK)
    prof = np.array(FOOT_PROFILE)
    prof_u = np.array([0.0, ankle_u, ball_u, 1.0])
    u = np.concatenate(
        (np.linspace(0.0, ankle_u, 4), np.linspace(ankle_u, ball_u, 6)[1:], np.linspace(ball_u, 1.0, 5)[1:])
    )
    top_ref = prof[:, 2] * s
    top_ref[1] = max(top_ref[1], a[1] - floor + ANKLE_TOP_ABOVE_JOINT * s)
    top = floor + np.interp(u, prof_u, top_ref)
    half_w = np.interp(u, prof_u, prof[:, 1] * s)
    centres = heel + u[:, None] * length * f
    influences: list[Influence] = []
    for x in u:
        if toes is None or x <= ball_u - 0.08:
            influences.append(((ankle, 1.0),))
        elif x >= ball_u + 0.08:
            influences.append(((toes, 1.0),))
        else:
            influences.append(_blend(((ankle, 1.0),), ((toes, 1.0),), (x - ball_u + 0.08) / 0.16))
    return _sole_tube(centres, lateral, half_w, floor, top, influences)


def _ellipsoid(centre: Array, a: Array, b: Array, c: Array, joint: int) -> _Part:
    """An ellipsoid of semi-axis vectors ``a`` (its poles), ``b`` and ``c``, bound to ``joint``."""
    rings = 11
    theta = np.linspace(-0.5 * np.pi, 0.5 * np.pi, rings + 2)[1:-1]
    centres = centre[None] + np.sin(theta)[:, None] * a[None]
    scale = np.cos(theta)
    bn, cn = float(np.linalg.norm(b)), float(np.linalg.norm(c))
    influences: list[Influence] = [((joint, 1.0),)] * rings
    pole = float(np.linalg.norm(a)) * (1.0 - np.sin(theta[-1]))
    return _tube(
        centres, b / bn, c / cn, bn * scale, cn * scale, influences, caps=(0.0, 0.0), poles=(pole, pole)
    )


def _tube(
    centres: Array,
    u: Array,
    v: Array,
    half_u: Array,
    half_v: Array,
    influences: Sequence[Influence],
    *,
    caps: tuple[float, float],
    poles: tuple[float, float] | None = None,
) -> _Part:
    """A closed tube of elliptic rings (``half_u`` along ``u``, ``half_v`` along ``v``) around
    ``centres (K, 3)``, closed at each end by a rounded cap (``caps``: its depth as a fraction of
    the end ring's radius) or a pole at the given distance (``poles``)."""
    k = len(centres)
    axis = np.gradient(centres, axis=0) if k > 1 else np.tile(np.cross(u, v), (1, 1))
    phi = np.linspace(0.0, 2.0 * np.pi, AROUND, endpoint=False)
    cos, sin = np.cos(phi), np.sin(phi)
    hu = np.broadcast_to(np.asarray(half_u, dtype=np.float64), (k,))
    hv = np.broadcast_to(np.asarray(half_v, dtype=np.float64), (k,))
    ring = (
        centres[:, None]
        + hu[:, None, None] * cos[None, :, None] * u
        + hv[:, None, None] * sin[None, :, None] * v
    )
    return _closed(ring, centres, axis, caps, influences, poles)


def _sole_tube(
    centres: Array,
    lateral: Array,
    half_w: Array,
    floor: float,
    top: Array,
    influences: Sequence[Influence],
) -> _Part:
    """The foot: rings whose upper half is round and lower half a square-edged flat sole exactly
    on the floor (a superellipse below the ring's middle), heel and toe closed by caps."""
    phi = np.linspace(0.0, 2.0 * np.pi, AROUND, endpoint=False)
    cos, sin = np.cos(phi), np.sin(phi)
    below = sin < 0
    shape_x = np.where(below, np.sign(cos) * np.abs(cos) ** SOLE_SQUARENESS, cos)
    shape_y = np.where(below, -np.minimum(1.0, SOLE_FLATNESS * np.abs(sin) ** SOLE_SQUARENESS), sin)
    half_h = 0.5 * (top - floor)
    mid = floor + half_h
    up = np.array([0.0, 1.0, 0.0])
    ring = (
        centres[:, None] * np.array([1.0, 0.0, 1.0])
        + (mid[:, None, None] + half_h[:, None, None] * shape_y[None, :, None]) * up
        + half_w[:, None, None] * shape_x[None, :, None] * lateral
    )
    ring[..., 1] = np.maximum(ring[..., 1], floor)
    mids = centres * np.array([1.0, 0.0, 1.0]) + mid[:, None] * up
    axis = np.gradient(mids, axis=0)
    return _closed(ring, mids, axis, (0.35, 0.25), influences, None, floor=floor)


def _closed(
    ring: Array,
    centres: Array,
    axis: Array,
    caps: tuple[float, float],
    influences: Sequence[Influence],
    poles: tuple[float, float] | None,
    floor: float | None = None,
) -> _Part:
    """Rings ``(K, N, 3)`` joined into quads, each end closed by two shrinking rings and a pole
    (a rounded cap); weights per ring from ``influences``."""
    k, n, _ = ring.shape
    rings = [ring[i] for i in range(k)]
    inf = list(influences)
    ends: list[tuple[Array, Influence]] = []
    for side, (index, sign) in enumerate(((0, -1.0), (k - 1, 1.0))):
        d = _unit(axis[index] * sign, np.array([0.0, 1.0, 0.0]))
        radius = float(np.mean(np.linalg.norm(ring[index] - centres[index], axis=-1)))
        depth = (poles[side] if poles is not None else caps[side] * radius) if radius > 0 else 0.0
        extra = []
        for frac, shrink in ((0.55, 0.82), (0.88, 0.45)):
            pts = centres[index] + shrink * (ring[index] - centres[index]) + d * depth * frac
            if floor is not None:
                pts[:, 1] = np.maximum(pts[:, 1], floor)
            extra.append(pts)
        pole = centres[index] + d * depth
        if floor is not None:
            pole[1] = max(pole[1], floor)
        ends.append((pole, inf[index]))
        if index == 0:
            rings = extra[::-1] + rings
            inf = [inf[0], inf[0], *inf]
        else:
            rings = rings + extra
            inf = [*inf, inf[-1], inf[-1]]
    stack = np.stack(rings)  # (R, N, 3)
    r = len(stack)
    positions = np.concatenate((stack.reshape(-1, 3), ends[0][0][None], ends[1][0][None]))
    idx = np.arange(r * n).reshape(r, n)
    nxt = np.roll(idx, -1, axis=1)
    a, b, c, dd = idx[:-1], nxt[:-1], nxt[1:], idx[1:]
    quads = np.concatenate((np.stack((a, c, b), -1).reshape(-1, 3), np.stack((a, dd, c), -1).reshape(-1, 3)))
    first, last = r * n, r * n + 1
    fan0 = np.stack((np.full(n, first), idx[0, :], nxt[0, :]), -1)
    fan1 = np.stack((np.full(n, last), nxt[-1, :], idx[-1, :]), -1)
    tri = np.concatenate((quads, fan0, fan1)).astype(np.intp)
    tri = _outward(positions, tri)
    ring_joints, ring_weights = _influence_table([*inf, ends[0][1], ends[1][1]])
    per_ring = np.concatenate((np.repeat(np.arange(r), n), [r, r + 1]))  # each vertex's ring (poles last)
    joints, weights = ring_joints[per_ring], ring_weights[per_ring]
    return _Part(positions, tri, joints, weights)


def _influence_table(influences: Sequence[Influence]) -> tuple[npt.NDArray[np.intp], Array]:
    """``(R, 4)`` joints and weights of each influence: a joint named twice summed, the four
    heaviest kept, renormalised to sum 1; unused slots joint 0 with weight 0 (as glTF asks)."""
    joints = np.zeros((len(influences), INFLUENCES), dtype=np.intp)
    weights = np.zeros((len(influences), INFLUENCES))
    for i, influence in enumerate(influences):
        merged: dict[int, float] = {}
        for j, w in influence:
            merged[j] = merged.get(j, 0.0) + w
        top = sorted(((j, w) for j, w in merged.items() if w > 1e-6), key=lambda jw: -jw[1])[:INFLUENCES]
        total = sum(w for _, w in top)
        for slot, (j, w) in enumerate(top):
            joints[i, slot] = j
            weights[i, slot] = w / total
    return joints, weights


def _outward(positions: Array, tri: npt.NDArray[np.intp]) -> npt.NDArray[np.intp]:
    """The triangles wound so that the closed surface's signed volume is positive
    (counter-clockwise seen from outside)."""
    p0, p1, p2 = positions[tri[:, 0]], positions[tri[:, 1]], positions[tri[:, 2]]
    volume = float(np.einsum("ij,ij->i", p0, np.cross(p1, p2)).sum())
    return tri if volume >= 0 else tri[:, [0, 2, 1]]


def _merged(parts: Sequence[_Part]) -> SkinnedMesh:
    """All parts in one mesh, with smooth normals within each part."""
    positions, triangles, joints, weights, normals = [], [], [], [], []
    base = 0
    for part in parts:
        positions.append(part.positions)
        triangles.append(part.triangles + base)
        joints.append(part.joints)
        weights.append(part.weights)
        normals.append(_vertex_normals(part.positions, part.triangles))
        base += len(part.positions)
    return SkinnedMesh(
        np.concatenate(positions),
        np.concatenate(normals),
        np.concatenate(joints).astype(np.uint16),
        np.concatenate(weights).astype(np.float32),
        np.concatenate(triangles).astype(np.uint32),
    )


def _vertex_normals(positions: Array, tri: npt.NDArray[np.intp]) -> Array:
    """Area-weighted vertex normals, unit length."""
    face = np.cross(positions[tri[:, 1]] - positions[tri[:, 0]], positions[tri[:, 2]] - positions[tri[:, 0]])
    out = np.zeros_like(positions)
    for k in range(3):
        np.add.at(out, tri[:, k], face)
    norm = np.linalg.norm(out, axis=-1, keepdims=True)
    return np.asarray(np.where(norm > 0, out / np.maximum(norm, 1e-30), [0.0, 1.0, 0.0]))


# ------------------------------------------------------------------------------------------------
# small vector helpers
# ------------------------------------------------------------------------------------------------


def _unit(v: Array, fallback: Array) -> Array:
    n = float(np.linalg.norm(v))
    return np.asarray(v / n) if n > 1e-12 else np.asarray(fallback, dtype=np.float64)


def _least_parallel(d: Array) -> Array:
    return np.asarray(np.eye(3)[int(np.argmin(np.abs(d)))])


def _blend(a: Influence, b: Influence, t: float) -> Influence:
    """``a`` and ``b`` mixed, ``b`` by a smooth step of ``t`` (0 = all ``a``)."""
    w = float(np.clip(t, 0.0, 1.0))
    w = w * w * (3.0 - 2.0 * w)
    return tuple((j, (1.0 - w) * x) for j, x in a) + tuple((j, w * x) for j, x in b)
