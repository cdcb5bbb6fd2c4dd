"""The ground-plane frame of a body: floor position and heading per frame, and the explicit
ground root joint used by exports.

Conventions (DESIGN.md): Y up; floor positions are ``[x, z]``; heading is the facing direction as
a rotation about +Y, 0 = facing +Z, +pi/2 = facing +X (the body's left is +X when it faces +Z).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import replace
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .align import apply_rigid_2d
from .errors import MotionError
from .mirror import mirror_map
from .motion import Motion
from .skeleton import Skeleton

Array = npt.NDArray[np.float64]

_THIGH_NAMES = re.compile(r"thigh|upleg|upperleg|femur", re.IGNORECASE)
_HIP_NAMES = re.compile(r"thigh|upleg|upperleg|femur|hip|buttock", re.IGNORECASE)
_SHOULDER_NAMES = re.compile(
    r"shoulder|shldr|upperarm|uparm|humerus|collar|clavicle|^[lr]?arm$", re.IGNORECASE
)


def facing_pairs(skeleton: Skeleton) -> list[tuple[int, int]]:
    """``(left, right)`` joint pairs whose difference points to the body's left: the hips (thighs)
    when their names say so, else the shoulders, else the paired joints nearest the root.

    The hips alone define the facing: the shoulders counter-rotate against the pelvis by several
    degrees at every step, and the pelvis is what carries the body (and root motion). Found once
    per joint hierarchy (names and parents)."""
    return list(_facing_pairs(skeleton.names, tuple(int(p) for p in skeleton.parents)))


@lru_cache(maxsize=256)
def _facing_pairs(names: tuple[str, ...], parents: tuple[int, ...]) -> tuple[tuple[int, int], ...]:
    partner, side = mirror_map(names)
    lefts = [j for j in range(len(names)) if side[j] == 1]
    if not lefts:
        return ()
    depth = [0] * len(parents)
    for j in range(1, len(parents)):
        depth[j] = depth[parents[j]] + 1
    for pattern in (_THIGH_NAMES, _HIP_NAMES, _SHOULDER_NAMES):
        named = [j for j in lefts if pattern.search(names[j])]
        if named:
            j = min(named, key=lambda k: (depth[k], k))
            return ((j, int(partner[j])),)
    j = min(lefts, key=lambda k: (depth[k], k))
    return ((j, int(partner[j])),)


def body_root(skeleton: Skeleton) -> int:
    """The joint that carries the body: the nearest common ancestor of the hip (thigh) joints
    (``Hips`` in Bandai-Namco files, whose joint 0 is a static ``joint_Root``; ``hip`` in CMU
    files), or joint 0 when there are no left/right hips."""
    pairs = facing_pairs(skeleton)
    if not pairs or not _HIP_NAMES.search(skeleton.names[pairs[0][0]]):
        return 0
    left, right = pairs[0]
    ancestors = set()
    j = left
    while j >= 0:
        ancestors.add(j)
        j = int(skeleton.parents[j])
    j = right
    while j not in ancestors:
        j = int(skeleton.parents[j])
    return j


def body_joints(skeleton: Skeleton) -> npt.NDArray[np.intp]:
    """``(K,)`` the joints of the body: :func:`body_root` and its descendants, so a static
    reference joint above the hips (Bandai-Namco's ``joint_Root``) is not one."""
    root = body_root(skeleton)
    inside = np.zeros(skeleton.num_joints, dtype=bool)
    inside[root] = True
    for j in range(root + 1, skeleton.num_joints):  # parents precede children
        p = int(skeleton.parents[j])
        inside[j] = p >= 0 and bool(inside[p])
    return np.flatnonzero(inside).astype(np.intp)


def heading(motion: Motion, positions: Array | None = None) -> Array:
    """``(F,)`` facing direction (radians about +Y; 0 = +Z, pi/2 = +X), unwrapped over time.

    From the floor projection of the left-minus-right vector of the hips (see
    :func:`facing_pairs`): forward = left x up. Skeletons without left/right names fall back to
    the root joint's rotated +Z axis.
    """
    if not facing_pairs(motion.skeleton):
        return np.unwrap(rot.yaw(motion.rotations[:, 0]))
    pos = motion.global_positions() if positions is None else positions
    facing = facing_from_positions(motion.skeleton, pos)
    if facing is None:  # pragma: no cover - facing_pairs found pairs above
        raise MotionError("no left/right joints to face by")
    return facing


def facing_from_positions(skeleton: Skeleton, positions: Array) -> Array | None:
    """``(F,)`` unwrapped heading (radians) from joint ``positions (F, J, 3)`` alone (the hips'
    left-minus-right vector, :func:`facing_pairs`); ``None`` when the skeleton has no left/right
    joints."""
    pairs = facing_pairs(skeleton)
    if not pairs:
        return None
    across = np.zeros((positions.shape[0], 3))
    for left, right in pairs:
        v = positions[:, left] - positions[:, right]
        n = np.linalg.norm(v[:, [0, 2]], axis=-1, keepdims=True)
        across += v / np.maximum(n, 1e-12)
    # forward = across x up = (-across_z, 0, across_x)
    return np.asarray(np.unwrap(np.arctan2(-across[:, 2], across[:, 0])))


def ground_frames(motion: Motion, positions: Array | None = None) -> tuple[Array, Array]:
    """Per frame, the body's floor position ``(F, 2)`` ``[x, z]`` (the :func:`body_root` joint
    projected on the floor) and the heading ``(F,)`` radians."""
    pos = motion.global_positions() if positions is None else positions
    return np.asarray(pos[:, body_root(motion.skeleton)][:, [0, 2]]), heading(motion, pos)


def to_ground_frame(points: Array, origin_xz: Array, heading_rad: Array) -> Array:
    """Express points ``(F, ..., 3)`` in each frame's ground frame: origin at ``origin_xz (F, 2)`` on
    the floor (heights unchanged), +Z along the heading ``(F,)``, +X to the body's left."""
    p = np.array(points, dtype=np.float64, copy=True)
    extra = (1,) * (p.ndim - 2)
    ox = origin_xz[:, 0].reshape(-1, *extra)
    oz = origin_xz[:, 1].reshape(-1, *extra)
    c = np.cos(heading_rad).reshape(-1, *extra)
    s = np.sin(heading_rad).reshape(-1, *extra)
    x = p[..., 0] - ox
    z = p[..., 2] - oz
    # rotate by -heading about +Y
    p[..., 0] = c * x - s * z
    p[..., 2] = s * x + c * z
    return p


def from_ground_frame(points: Array, origin_xz: Array, heading_rad: Array) -> Array:
    """Inverse of :func:`to_ground_frame`."""
    p = np.array(points, dtype=np.float64, copy=True)
    extra = (1,) * (p.ndim - 2)
    c = np.cos(heading_rad).reshape(-1, *extra)
    s = np.sin(heading_rad).reshape(-1, *extra)
    x, z = p[..., 0].copy(), p[..., 2].copy()
    p[..., 0] = c * x + s * z + origin_xz[:, 0].reshape(-1, *extra)
    p[..., 2] = -s * x + c * z + origin_xz[:, 1].reshape(-1, *extra)
    return p


def smooth_signal(x: Array, window: int) -> Array:
    """Centred moving average over ``window`` frames (odd), edges padded by reflection."""
    if window <= 1 or x.shape[0] < 2:
        return np.asarray(x, dtype=np.float64)
    w = window | 1
    half = w // 2
    pad = np.pad(x, [(half, half)] + [(0, 0)] * (x.ndim - 1), mode="reflect" if x.shape[0] > half else "edge")
    c = np.cumsum(pad, axis=0)
    c = np.concatenate((np.zeros((1, *x.shape[1:])), c), axis=0)
    return np.asarray((c[w:] - c[:-w]) / w)


GROUND_ROOT_NAME = "ground"


def add_ground_root(motion: Motion, *, name: str = GROUND_ROOT_NAME, smooth_s: float = 0.0) -> Motion:
    """A copy of the motion under an explicit ground root joint (for root motion in engines).

    The new joint 0 sits on the floor (y = 0) under the old root, rotated about +Y by the heading;
    the old root becomes its child, animated relative to it (its BVH channels gain positions).
    Global positions of all original joints are unchanged.

    Parameters
    ----------
    name:
        Name of the new root (must not already exist).
    smooth_s:
        Width in seconds of a moving average applied to the ground path and heading (0 = none),
        for a steadier root motion.
    """
    sk = motion.skeleton
    if name in sk.names:
        raise MotionError(f"the skeleton already has a joint named {name!r}")
    pos = motion.global_positions()
    xz, yaw = ground_frames(motion, pos)
    window = int(round(smooth_s * motion.fps))
    if window > 1:
        xz, yaw = smooth_signal(xz, window), smooth_signal(yaw, window)
    ground_pos = np.stack((xz[:, 0], np.zeros(motion.num_frames), xz[:, 1]), axis=-1)
    ground_rot = rot.from_yaw(yaw)
    inv = rot.conjugate(ground_rot)
    old_root_local_pos = rot.rotate(inv, motion.root_positions - ground_pos)
    old_root_local_rot = rot.multiply(inv, motion.rotations[:, 0])

    old_channels = sk.channels[0]
    root_channels = (
        old_channels
        if any(c.endswith("position") for c in old_channels)
        else ("Xposition", "Yposition", "Zposition", *old_channels)
    )
    new_sk = Skeleton(
        (name, *sk.names),
        np.concatenate(([-1], sk.parents + 1)),
        np.concatenate((np.zeros((1, 3)), sk.offsets)),
        (
            ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),
            root_channels,
            *sk.channels[1:],
        ),
        sk.end_site_parents + 1,
        sk.end_site_offsets,
    )
    # joint 1 (the old root) now carries animated translations, ahead of the previous ones
    jt = np.concatenate((old_root_local_pos[:, None], motion.joint_translations), axis=1)
    rotations = np.concatenate(
        (ground_rot[:, None], old_root_local_rot[:, None], motion.rotations[:, 1:]), axis=1
    )
    return replace(
        motion, skeleton=new_sk, root_positions=ground_pos, rotations=rotations, joint_translations=jt
    )


StaticRoot = tuple[Array, Array]
"""Joint 0's fixed position ``(3,)`` (file units) and rotation ``(4,)`` (x, y, z, w)."""


def static_reference_root(motions: Sequence[Motion]) -> StaticRoot | None:
    """Joint 0's position and rotation when it is one fixed pose in every frame of every motion and
    all its children carry animated translations (Bandai-Namco's ``joint_Root`` at the origin, the
    body carried by the translated ``Hips``); else ``None``.

    Moving such a reference joint (placing or smoothing pieces of motion) would swing the whole
    body about the origin; :func:`apply_floor_transform` moves its children instead.
    """
    if not motions:
        return None
    first = motions[0]
    sk = first.skeleton
    children = np.flatnonzero(sk.parents == 0)
    if children.size == 0 or not np.all(np.isin(children, sk.translated_joints)):
        return None
    p0, q0 = first.root_positions[0], rot.standardize(first.rotations[0, 0])
    for m in motions:
        if np.abs(m.root_positions - p0).max() > 1e-9:
            return None
        if np.abs(rot.standardize(m.rotations[:, 0]) - q0).max() > 1e-9:
            return None
    return p0, q0


def usual_reference_root(motions: Sequence[Motion]) -> tuple[StaticRoot | None, npt.NDArray[np.bool_]]:
    """Joint 0's fixed pose in the motions where it never moves, when those motions agree on one
    pose and hold at least half of all frames and joint 0's children all carry animated
    translations (else ``None``), and per motion ``(M,)`` whether its joint 0 leaves that pose
    (all false without one). The pose is :func:`static_reference_root`'s when every motion keeps
    it fixed.

    Four Bandai-Namco clips (``dataset-1`` ``dash``, ``run``, ``walk-back`` and ``walk_002``)
    translate ``joint_Root`` as well as ``Hips``: a library holding one of them has no static
    reference root by the strict rule, and cut smoothing then swings whole bodies about the
    origin. :func:`pin_reference_root` brings such motions to this pose. One pass over the
    concatenated frames (a million frames in a few tens of milliseconds)."""
    moving = np.zeros(len(motions), dtype=bool)
    if not motions:
        return None, moving
    sk = motions[0].skeleton
    children = np.flatnonzero(sk.parents == 0)
    if children.size == 0 or not np.all(np.isin(children, sk.translated_joints)):
        return None, moving
    counts = np.array([m.num_frames for m in motions], dtype=np.int64)
    live = [int(i) for i in np.flatnonzero(counts > 0)]
    if not live:
        return None, moving
    p = np.concatenate([motions[i].root_positions for i in live])
    # joint 0's column copied clip by clip (not views holding every clip's whole rotations at once)
    q = rot.standardize(np.concatenate([motions[i].rotations[:, 0].copy() for i in live]))
    starts = np.concatenate(([0], np.cumsum(counts[live])[:-1]))
    first = np.repeat(starts, counts[live])
    dev = np.maximum(np.abs(p - p[first]).max(axis=1), np.abs(q - q[first]).max(axis=1))
    fixed = np.maximum.reduceat(dev, starts) <= 1e-9
    if not fixed.any():
        return None, moving
    k = starts[fixed]
    p0, q0 = p[k[0]].copy(), q[k[0]].copy()
    if np.abs(p[k] - p0).max() > 1e-9 or np.abs(q[k] - q0).max() > 1e-9:
        return None, moving
    if 2 * int(counts[live][fixed].sum()) < int(counts.sum()):
        return None, moving
    moving[np.asarray(live)[~fixed]] = True
    return (p0, q0), moving


def pin_reference_root(motion: Motion, static: StaticRoot) -> Motion:
    """The motion with joint 0 held at the pose ``static`` in every frame and its children
    re-expressed so that every other joint's global position and rotation is unchanged (joint 0's
    own motion moves into its children, which must carry animated translations)."""
    p0, q0 = static
    sk = motion.skeleton
    pr, qr = motion.root_positions, motion.rotations[:, 0]
    q0i = rot.conjugate(q0)[None]
    q = motion.rotations.copy()
    jt = motion.joint_translations.copy()
    tj = list(sk.translated_joints)
    for c in np.flatnonzero(sk.parents == 0):
        if int(c) not in tj:
            name = sk.names[int(c)]
            raise MotionError(f"joint {name!r} under the reference root has no translation channels")
        k = tj.index(int(c))
        world = rot.rotate(qr, jt[:, k]) + pr
        jt[:, k] = rot.rotate(q0i, world - p0)
        q[:, c] = rot.multiply(q0i, rot.multiply(qr, q[:, c]))
    q[:, 0] = q0
    root = np.repeat(np.asarray(p0, dtype=np.float64)[None], motion.num_frames, axis=0)
    return replace(motion, root_positions=root, rotations=q, joint_translations=jt)


def pin_reference_roots(motions: Sequence[Motion]) -> tuple[StaticRoot | None, tuple[Motion, ...]]:
    """The motions' usual static reference root (:func:`usual_reference_root`) and the motions
    with every one whose joint 0 leaves it pinned to it (:func:`pin_reference_root`: the same
    global poses; the others are the very objects given); the motions as they are when there is
    none. Assembly places and smooths such pinned clips without swinging joint 0 (and the body
    hung from it) about the origin."""
    static, moving = usual_reference_root(motions)
    if static is None or not moving.any():
        return static, tuple(motions)
    return static, tuple(pin_reference_root(m, static) if moving[i] else m for i, m in enumerate(motions))


def apply_floor_transform(
    motion: Motion, theta: Array, shift_m: Array, static: StaticRoot | None = None
) -> Motion:
    """The motion with frame ``f`` rotated by ``theta[f]`` (radians about +Y, about the world origin)
    then moved by ``shift_m[f]`` (``[x, z]`` metres), ``theta: (F,)``, ``shift_m: (F, 2)``.

    With a static reference root (:func:`static_reference_root`), joint 0 stays put and the global
    transforms of its children move instead (re-expressed in joint 0's frame), so the result's
    global joint positions are the same as if joint 0 had moved.
    """
    shift_u = np.asarray(shift_m, dtype=np.float64) / motion.metres_per_unit
    theta = np.asarray(theta, dtype=np.float64)
    turn = rot.from_yaw(theta)  # (F, 4)
    if static is None:
        root = apply_rigid_2d(motion.root_positions[:, None, :], theta, shift_u)[:, 0]
        q = motion.rotations.copy()
        q[:, 0] = rot.multiply(turn, q[:, 0])
        return replace(motion, root_positions=root, rotations=q)
    p0, q0 = static
    sk = motion.skeleton
    q = motion.rotations.copy()
    jt = motion.joint_translations.copy()
    q0i = rot.conjugate(q0)
    local_turn = rot.multiply(rot.multiply(q0i[None], turn), q0[None])  # q0^-1 R q0
    tj = list(sk.translated_joints)
    for c in np.flatnonzero(sk.parents == 0):
        k = tj.index(int(c))
        glob = rot.rotate(q0[None], jt[:, k]) + p0
        moved = apply_rigid_2d(glob[:, None, :], theta, shift_u)[:, 0]
        jt[:, k] = rot.rotate(q0i[None], moved - p0)
        q[:, c] = rot.multiply(local_turn, q[:, c])
    return replace(motion, rotations=q, joint_translations=jt)
