"""Rotation transfer through the two rest poses, and the root path scaled by leg length.

Each character joint driven by a source joint gets a world rotation computed from world-space
bone directions, never from raw Euler values, so the two skeletons may differ in rest pose,
joint axes, channel order, proportions and units:

* an *aimed* joint (one driven child below it: an upper arm, a shin, a spine joint) turns so that
  its bone, from the joint to the driven child, points where the source's bone points in that
  frame. The twist about the bone comes from the source joint's rotation since its rest, carried
  over by the shortest arc that takes the source's rest bone onto the character's rest bone;
* a *branching* joint (hips, chest: a centre child and a left and right one) takes the whole
  frame spanned by its up direction (to the centre child) and its left-right axis (right child to
  left child), so the pelvis and the shoulders face where the source's do;
* a *leaf* (hands, head, toes without a driven child) turns with the source joint, rotated into
  the character by its parent's rest alignment.

Joints without a source (the character's extra spine joints, twist bones, fingers) keep their
rest rotation, relative to their parent. The hips follow the source's hips scaled by the ratio of
the two skeletons' hip heights in the same poses (the median height of the hips above the ankles,
source and transferred character; thigh plus shin lengths for a motion that rarely stands), their
height measured from each skeleton's standing ankle height (the source's usual lowest ankle level;
the character's lower ankle in its rest pose, or the source's level scaled when that pose is not
standing), so the character's feet meet its own floor. Only rotations and the
translation of the root (or the translated joint that carries the hips) change: the character's
bone offsets, channels and units are kept exactly.

Source rest pose: its zero-rotation pose (any reference pose gives the same bone directions; it
only sets how twist is carried over). Character rest pose: frame 0 of the character motion.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..contacts import detect_contacts
from ..errors import MotionError
from ..motion import Motion
from ..skeleton import Skeleton
from .names import Correspondence

Array = npt.NDArray[np.float64]
_EPS = 1e-9


def shortest_arc(a: Array, b: Array) -> Array:
    """Unit quaternions ``(..., 4)`` of the smallest rotation taking directions ``a`` onto ``b``
    (``(..., 3)``, any length; broadcast). Opposite directions turn half about a perpendicular axis."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    na = np.linalg.norm(a, axis=-1, keepdims=True)
    nb = np.linalg.norm(b, axis=-1, keepdims=True)
    ua, ub = a / np.maximum(na, 1e-300), b / np.maximum(nb, 1e-300)
    q = np.concatenate((np.cross(ua, ub), 1.0 + np.sum(ua * ub, axis=-1, keepdims=True)), axis=-1)
    bad = q[..., 3] < 1e-9
    if np.any(bad):
        perp = np.cross(ua[bad], np.array([1.0, 0.0, 0.0]))
        weak = np.linalg.norm(perp, axis=-1) < 1e-6
        perp[weak] = np.cross(ua[bad][weak], np.array([0.0, 1.0, 0.0]))
        q[bad] = np.concatenate((perp, np.zeros(perp.shape[:-1] + (1,))), axis=-1)
    zero = (na[..., 0] < 1e-300) | (nb[..., 0] < 1e-300)
    q[zero] = rot.IDENTITY
    return np.asarray(q / np.linalg.norm(q, axis=-1, keepdims=True))


def frame_matrix(up: Array, lateral: Array) -> Array:
    """Rotation matrices ``(..., 3, 3)`` with columns (lateral, up, forward): ``up`` exactly,
    ``lateral`` made perpendicular to it (``(..., 3)`` each)."""
    y = up / np.maximum(np.linalg.norm(up, axis=-1, keepdims=True), 1e-300)
    x = lateral - np.sum(lateral * y, axis=-1, keepdims=True) * y
    x = x / np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), 1e-300)
    z = np.cross(x, y)
    return np.stack((x, y, z), axis=-1)


def _frame(up: Array, lateral: Array, what: str, rest: bool) -> Array:
    """:func:`frame_matrix` of ``up`` and ``lateral`` ``(F, 3)`` each, for frames where they span
    a plane. A frame where they do not (a zero-length bone, coincident joints, the left-right axis
    along the up direction) takes the nearest good frame's axes; a rest pose where they do not,
    or a motion with no good frame, is refused naming ``what`` (and the frame)."""
    nu = np.linalg.norm(up, axis=-1)
    scale = max(float(nu.max(initial=0.0)), float(np.linalg.norm(lateral, axis=-1).max(initial=0.0)), 1e-300)
    x = lateral - np.sum(lateral * up, axis=-1, keepdims=True) * up / np.maximum(nu, 1e-300)[:, None] ** 2
    good = (nu > 1e-6 * scale) & (np.linalg.norm(x, axis=-1) > 1e-6 * scale)
    if not good.all():
        first = int(np.flatnonzero(~good)[0])
        if rest or not good.any():
            where = "" if rest else f" in every frame (frame {first}, ...)"
            raise MotionError(f"{what} do not span a plane{where}: a zero-length bone or coincident joints")
        idx = np.flatnonzero(good)
        frames = np.arange(len(good))
        at = np.searchsorted(idx, frames)
        after, before = idx[np.minimum(at, len(idx) - 1)], idx[np.maximum(at - 1, 0)]
        pick = np.where(np.abs(frames - before) < np.abs(after - frames), before, after)
        up = np.where(good[:, None], up, up[pick])
        lateral = np.where(good[:, None], lateral, lateral[pick])
    return frame_matrix(up, lateral)


@dataclass(frozen=True)
class Pose:
    """World positions ``(F, J, 3)`` and rotations ``(F, J, 4)`` of a motion."""

    positions: Array
    rotations: Array

    @staticmethod
    def of(motion: Motion) -> Pose:
        pos, grot = motion.fk()
        return Pose(np.ascontiguousarray(pos), np.ascontiguousarray(grot))


def zero_pose(motion: Motion) -> Motion:
    """Frame 0 of ``motion`` with every rotation set to identity (its BVH rest pose)."""
    first = motion.slice(0, 1)
    return Motion(
        first.skeleton,
        first.root_positions,
        np.broadcast_to(rot.IDENTITY, first.rotations.shape).copy(),
        first.fps,
        first.joint_translations,
        first.units,
        first.name,
    )


def _driven_children(corr: Correspondence, parents: npt.NDArray[np.intp]) -> dict[int, list[int]]:
    """Driven character joint -> the driven joints whose nearest driven ancestor it is."""
    out: dict[int, list[int]] = {j: [] for j in corr.pairs}
    for j in corr.pairs:
        p = int(parents[j])
        while p >= 0 and p not in corr.pairs:
            p = int(parents[p])
        if p >= 0:
            out[p].append(j)
    return out


def leg_length(positions: Array, roles: dict[str, int]) -> float:
    """Mean over both legs of thigh plus shin length (hip-knee-ankle distances), ``positions``
    ``(J, 3)`` of one pose, in their units."""
    total = 0.0
    for side in ("Left", "Right"):
        h, k, a = (positions[roles[f"{side}{x}"]] for x in ("UpperLeg", "LowerLeg", "Foot"))
        total += float(np.linalg.norm(k - h) + np.linalg.norm(a - k))
    return total / 2.0


def _aimed(u_t0: Array, u_s0: Array, u_s: Array, gs: Array, gs0: Array, gt0: Array) -> tuple[Array, Array]:
    """An aimed joint: its rest alignment (shortest arc from the source's rest bone ``u_s0`` to the
    character's ``u_t0``) and its world rotations ``(F, 4)``: the source's rotation since its rest
    (``gs (F, 4)`` from ``gs0``), carried over by that arc, then swung so the bone points along the
    source's ``u_s (F, 3)``."""
    a = shortest_arc(u_s0, u_t0)
    delta = rot.multiply(gs, rot.inverse(rot.multiply(a, gs0)))
    swing = shortest_arc(rot.rotate(delta, u_t0), u_s)
    return a, rot.multiply(swing, rot.multiply(delta, gt0))


def tip_positions(motion: Motion, pose: Pose) -> Array:
    """``(F, J, 3)`` where each joint's bone ends, for leaves of the correspondence: down a chain
    of single children to its end, the mean of the joint's child joints and End Sites there (a
    foot's toe tip, a hand's finger roots). A joint without either gets its own position."""
    sk = motion.skeleton
    ends = motion.end_site_positions(pose.positions, pose.rotations) if sk.end_site_parents.size else None
    kids = [sk.children(j) for j in range(sk.num_joints)]
    sites = [np.flatnonzero(sk.end_site_parents == j) for j in range(sk.num_joints)]
    out = np.array(pose.positions, copy=True)
    for j in range(sk.num_joints):
        k = j
        while len(kids[k]) == 1 and sites[k].size == 0:
            k = kids[k][0]
        parts = [pose.positions[:, kids[k]]] if kids[k] else []
        if ends is not None and sites[k].size:
            parts.append(ends[:, sites[k]])
        if parts:
            out[:, j] = np.concatenate(parts, axis=1).mean(axis=1)
        elif k != j:
            out[:, j] = pose.positions[:, k]
    return out


def transfer_rotations(
    source: Motion, character: Motion, corr: Correspondence, src_pose: Pose | None = None
) -> Array:
    """Local rotations ``(F, J_character, 4)`` of the character following ``source`` (module
    docstring). ``character``: its frame 0 is the rest pose; ``src_pose``: ``Pose.of(source)``."""
    sp = Pose.of(source) if src_pose is None else src_pose
    s0 = Pose.of(zero_pose(source))
    t0 = Pose.of(character.slice(0, 1))
    ps, gs, ps0, gs0 = sp.positions, sp.rotations, s0.positions[0], s0.rotations[0]
    pt0, gt0 = t0.positions[0], t0.rotations[0]
    sk = character.skeleton
    n, nj = source.num_frames, sk.num_joints
    children = _driven_children(corr, sk.parents)
    side = corr.side(sk)
    t_tips = tip_positions(character.slice(0, 1), t0)
    s_tips = tip_positions(zero_pose(source), s0)
    s_tip_all: Array | None = None

    def s_tip(joint: int) -> Array:
        nonlocal s_tip_all
        if s_tip_all is None:
            s_tip_all = tip_positions(source, sp)
        return s_tip_all[:, joint]

    tol_t = 1e-6 * float(np.abs(sk.offsets[1:]).max(initial=1.0))
    tol_s = 1e-6 * float(np.abs(source.skeleton.offsets[1:]).max(initial=1.0))

    def reach(j: int, c: int) -> int:
        """``c``, or the first driven joint below it that is not at ``j``'s place in either rest
        pose (a zero-length bone, e.g. CMU's lowerback at the hips, gives no direction)."""
        s = corr.pairs[j]
        while (
            np.linalg.norm(pt0[c] - pt0[j]) <= tol_t or np.linalg.norm(ps0[corr.pairs[c]] - ps0[s]) <= tol_s
        ) and children[c]:
            nxt = [k for k in children[c] if side.get(k, 0) == 0] or children[c]
            c = nxt[0]
        return c

    def apart(lt: int, rt: int) -> tuple[int, int]:
        """The left and right joints to span a branching joint's left-right axis with: ``lt`` and
        ``rt``, or the first driven joints below them that are apart in both rest poses (collars
        that start where the chest ends, at one point, give no axis; their shoulders do)."""
        while np.linalg.norm(pt0[lt] - pt0[rt]) <= tol_t or (
            np.linalg.norm(ps0[corr.pairs[lt]] - ps0[corr.pairs[rt]]) <= tol_s
        ):
            if not (children[lt] and children[rt]):
                break
            lt, rt = children[lt][0], children[rt][0]
        return lt, rt

    align: dict[int, Array] = {}
    desired: dict[int, Array] = {}
    for j in range(nj):  # parents first: a leaf needs its parent's alignment
        if j not in corr.pairs:
            continue
        s = corr.pairs[j]
        kids = children[j]
        centre = [reach(j, c) for c in kids if side.get(c, 0) == 0]
        left = [reach(j, c) for c in kids if side.get(c, 0) > 0]
        right = [reach(j, c) for c in kids if side.get(c, 0) < 0]
        if left and right:
            lt, rt = apart(left[0], right[0])
            ls, rs = corr.pairs[lt], corr.pairs[rt]
            if centre:
                up_t0 = pt0[centre[0]] - pt0[j]
                up_s0 = ps0[corr.pairs[centre[0]]] - ps0[s]
                up_s = ps[:, corr.pairs[centre[0]]] - ps[:, s]
            else:  # no centre child: up is away from the two side children
                up_t0 = 2 * pt0[j] - pt0[lt] - pt0[rt]
                up_s0 = 2 * ps0[s] - ps0[ls] - ps0[rs]
                up_s = 2 * ps[:, s] - ps[:, ls] - ps[:, rs]
            what = f"{source.skeleton.names[s]}'s up and left-right axes"
            ft0 = _frame(up_t0[None], (pt0[lt] - pt0[rt])[None], f"the character's {sk.names[j]}", True)[0]
            fs0 = _frame(up_s0[None], (ps0[ls] - ps0[rs])[None], f"the source's rest pose: {what}", True)[0]
            fs = _frame(up_s, ps[:, ls] - ps[:, rs], f"the source: {what}", False)
            align[j] = rot.from_matrix(ft0 @ fs0.T)
            desired[j] = rot.multiply(rot.from_matrix(fs @ ft0.T), gt0[j])
        elif kids:
            c = centre[0] if centre else reach(j, kids[0])
            sc = corr.pairs[c]
            align[j], desired[j] = _aimed(
                pt0[c] - pt0[j], ps0[sc] - ps0[s], ps[:, sc] - ps[:, s], gs[:, s], gs0[s], gt0[j]
            )
        else:
            u_t0, u_s0 = t_tips[0, j] - pt0[j], s_tips[0, s] - ps0[s]
            if np.linalg.norm(u_t0) > tol_t and np.linalg.norm(u_s0) > tol_s:
                u_s = s_tip(s) - ps[:, s]
                align[j], desired[j] = _aimed(u_t0, u_s0, u_s, gs[:, s], gs0[s], gt0[j])
                continue
            p = int(sk.parents[j])
            while p >= 0 and p not in align:
                p = int(sk.parents[p])
            a = align[p] if p >= 0 else rot.IDENTITY
            align[j] = a
            delta = rot.multiply(gs[:, s], rot.inverse(rot.multiply(a, gs0[s])))
            desired[j] = rot.multiply(delta, gt0[j])
    for j, planted in planted_feet(source, character, corr, sp, t0).items():
        desired[j] = planted
    return np.asarray(
        rot.standardize(rot.normalize(locals_from_globals(sk, desired, character.rotations[0], n)))
    )


def locals_from_globals(sk: Skeleton, desired: Mapping[int, Array], rest_local: Array, n: int) -> Array:
    """``(n, J, 4)`` local rotations of skeleton ``sk`` whose joints in ``desired`` take those
    global rotations (``(n, 4)`` each, world frame) and whose other joints keep their local
    ``rest_local[j]`` (``(J, 4)``) under their posed parents."""
    glob = np.empty((n, sk.num_joints, 4))
    local = np.empty((n, sk.num_joints, 4))
    for j in range(sk.num_joints):
        p = int(sk.parents[j])
        if j in desired:
            glob[:, j] = desired[j]
            local[:, j] = glob[:, j] if p < 0 else rot.multiply(rot.inverse(glob[:, p]), glob[:, j])
        else:
            local[:, j] = rest_local[j]
            glob[:, j] = local[:, j] if p < 0 else rot.multiply(glob[:, p], local[:, j])
    return local


def floor_heading(positions: Array, left: int, right: int) -> Array:
    """``(F,)`` the body's heading (radians about +Y, 0 = +Z, unwrapped) from the floor direction
    of ``left - right`` joint positions ``(F, J, 3)`` crossed with up (forward = left x up)."""
    across = positions[:, left] - positions[:, right]
    forward = np.cross(across, np.array([0.0, 1.0, 0.0]))
    return np.asarray(np.unwrap(np.arctan2(forward[:, 0], forward[:, 2])))


MIN_PLANTED_FRAMES = 3


def planted_feet(
    source: Motion, character: Motion, corr: Correspondence, sp: Pose, t0: Pose
) -> dict[int, Array]:
    """World rotations ``(F, 4)`` of the character's feet (ankle joints), set so that a foot the
    source plants is the character's own planted foot: its rest-pose foot (sole and toe on its
    floor), turned by the body's heading.

    The source's planted foot is its usual orientation on its contact frames
    (:func:`motion.contacts.detect_contacts`), relative to the body's heading (the thighs'
    :func:`floor_heading`); off the floor the character's foot turns as the source's turns from
    that orientation. A skeleton's own joints, not the line from its ankle to its toe tip, decide
    what "flat" is, so a source whose foot axis is 15-20 degrees off the character's (CMU's
    ankle-to-toe-tip line against a game rig's ankle-to-ball bone) does not lift the toes. Feet
    the source never plants (fewer than 3 contact frames) are left out (they stay aimed).
    """
    sr, tr = corr.source_roles, corr.target_roles
    if not all(r in sr for r in ("LeftUpperLeg", "RightUpperLeg")):
        return {}
    heading = floor_heading(sp.positions, sr["LeftUpperLeg"], sr["RightUpperLeg"])
    rest_heading = float(floor_heading(t0.positions, tr["LeftUpperLeg"], tr["RightUpperLeg"])[0])
    out: dict[int, Array] = {}
    for role in ("LeftFoot", "RightFoot"):
        if role not in sr or role not in tr:
            continue
        s, j = sr[role], tr[role]
        try:
            _, flags = detect_contacts(source, np.array([s]), positions=sp.positions)
        except MotionError:
            continue
        frames = np.flatnonzero(flags[:, 0])
        if frames.size < MIN_PLANTED_FRAMES:
            continue
        local = rot.multiply(rot.from_yaw(-heading[frames]), sp.rotations[frames, s])
        local = np.where(np.sum(local * local[:1], axis=-1, keepdims=True) < 0, -local, local)
        flat = rot.normalize(local.mean(axis=0))  # the source's planted foot, heading 0
        rest = rot.multiply(rot.from_yaw(-rest_heading), t0.rotations[0, j])  # the character's
        out[j] = rot.multiply(sp.rotations[:, s], rot.multiply(rot.inverse(flat), rest))
    return out


def floor_height(positions: Array, feet: list[int]) -> float:
    """The standing height of the ankles: 5th percentile over frames of the lower ankle's height
    (``positions (F, J, 3)``)."""
    return float(np.percentile(positions[:, feet, 1].min(axis=1), 5))


def hip_height_ratio(
    source_positions: Array, target_positions: Array, corr: Correspondence, chain_ratio: float
) -> float:
    """The character's hip height over the source's in the same poses: the ratio of the median
    (over frames) heights of the hips above the mean of the two ankles, ``positions (F, J, 3)`` of
    the source and of the transferred character (any root placement). Falls back to
    ``chain_ratio`` (thigh plus shin lengths) when the motion rarely stands (a median drop under a
    quarter of the leg: crawling, lying)."""
    sr, tr = corr.source_roles, corr.target_roles

    def drop(p: Array, r: dict[str, int]) -> float:
        ankles = 0.5 * (p[:, r["LeftFoot"], 1] + p[:, r["RightFoot"], 1])
        return float(np.median(p[:, r["Hips"], 1] - ankles))

    ds, dt = drop(source_positions, sr), drop(target_positions, tr)
    s_leg = leg_length(source_positions[0], sr)
    if not (ds > 0.25 * s_leg and dt > 0 and np.isfinite(dt / ds)):
        return chain_ratio
    return dt / ds


def hips_path(
    source: Motion, character: Motion, corr: Correspondence, src_pose: Pose, transferred: Motion
) -> tuple[Array, float]:
    """Where the character's hips go, ``(F, 3)`` in its units, and the hip-height ratio
    (character / source, each in its own units; :func:`hip_height_ratio`). ``transferred``: the
    character with its rotations transferred (any root placement)."""
    s0 = Pose.of(zero_pose(source)).positions[0]
    t0 = Pose.of(character.slice(0, 1)).positions[0]
    chain = leg_length(t0, corr.target_roles) / max(leg_length(s0, corr.source_roles), 1e-300)
    if not (np.isfinite(chain) and chain > 0):
        raise MotionError("cannot scale the root: a skeleton has legs of zero length")
    ratio = hip_height_ratio(src_pose.positions, np.asarray(transferred.global_positions()), corr, chain)
    sr, tr = corr.source_roles, corr.target_roles
    s_feet, t_feet = [sr["LeftFoot"], sr["RightFoot"]], [tr["LeftFoot"], tr["RightFoot"]]
    hips = src_pose.positions[:, sr["Hips"]]
    s_floor = floor_height(src_pose.positions, s_feet)
    t_floor = float(t0[t_feet, 1].min())
    if t0[tr["Hips"], 1] - t_floor < 0.5 * leg_length(t0, tr):  # a rest pose not standing (lying, a
        t_floor = ratio * s_floor  # zero pose of a skeleton that lies down): the source's floor, scaled
    path = hips * ratio
    path[:, 1] = t_floor + ratio * (hips[:, 1] - s_floor)
    return path, ratio


def place_hips(motion: Motion, hips: int, path: Array) -> Motion:
    """``motion`` with its root (or the nearest translated joint at or above ``hips``) moved so that
    joint ``hips`` follows ``path (F, 3)`` (units of the motion)."""
    sk = motion.skeleton
    now = np.ascontiguousarray(motion.global_positions()[:, hips])
    shift = path - now
    carrier = hips
    translated = {int(j): k for k, j in enumerate(sk.translated_joints)}
    while carrier > 0 and carrier not in translated:
        carrier = int(sk.parents[carrier])
    if carrier == 0:
        return Motion(
            sk,
            motion.root_positions + shift,
            motion.rotations,
            motion.fps,
            motion.joint_translations,
            motion.units,
            motion.name,
        )
    _, grot = motion.fk()
    parent_rot = np.ascontiguousarray(grot[:, int(sk.parents[carrier])])
    jt = np.array(motion.joint_translations, copy=True)
    jt[:, translated[carrier]] += rot.rotate(rot.inverse(parent_rot), shift)
    return Motion(sk, motion.root_positions, motion.rotations, motion.fps, jt, motion.units, motion.name)
