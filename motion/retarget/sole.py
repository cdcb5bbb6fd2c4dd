"""A character's soles: the points of each foot that touch the floor (heel, ball, toe tip).

What stands on the floor is the skin of the foot, not its joints: an ankle joint sits 8-10 cm
above the floor inside the foot, a game rig's ball joint 2 cm; the heel's corner reaches below
the ankle's floor projection when the foot lands heel first, and the toe tip below the ball when
it pushes off. :class:`Sole` holds the points of one foot that can touch the floor, each bound to
the foot's bones as the character's skin binds it, so that :meth:`Sole.positions` deforms them as
a viewer deforms the mesh (linear blend skinning on those points):

* **from the skinned mesh** (:func:`mesh_soles`, a glTF/GLB character with a mesh): the vertices
  weighted mostly to the foot and its toes (at least half their weight in the foot's subtree),
  all of them, not only those near the floor in the rest pose (a source may turn a foot over: a
  flick that points the sole up puts the top of the foot lowest), reduced to the corners of
  their convex hull (heel and toe parts apart: the lowest point of a rigid set of points,
  however it turns, is a corner of its hull), with their own skin weights;
* **from the bones** (:func:`bone_soles`, a BVH character, a glTF skin without a mesh): a heel
  behind the ankle, the ball under the toe joint (or 70 % of the way from the heel to the tip
  without one) and the toe tip (the toe's End Site or child), each with an inner and an outer
  point half a foot width apart (:data:`FOOT_WIDTH` of its length), all at the height of the
  foot's lowest joint or tip in the rest pose (each foot its own: a rest pose taken from a clip
  may lift one foot; the rest foot is what the transfer plants flat).

Points are split into the heel part (moving with the foot bone) and the toe part (``on_toe``:
moving mostly with the toe bone, which bends at the ball when the heel lifts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..errors import MotionError
from ..motion import Motion
from ..skinning import BoundMesh
from .transfer import Pose, tip_positions

Array = npt.NDArray[np.float64]

SIDES = ("Left", "Right")
HEEL_BACK = 0.2
"""A bone sole's heel lies this fraction of the foot's length behind the ankle."""
BALL_AT = 0.7
"""Without a toe joint, the ball lies this far from the heel to the toe tip."""
FOOT_WIDTH = 0.38
"""A bone sole is this fraction of its length wide (an adult foot: 9-10 cm for 25-26 cm)."""
_MIN_WEIGHT = 1e-4
GUARD_SHARE = 0.25
"""Vertices with at least this share of their weight in a foot (and less than half) move enough
with it that lifting the foot lifts them: they are kept above the floor with it."""


@dataclass(frozen=True)
class Sole:
    """The floor-touching points of one foot.

    Attributes
    ----------
    side:
        ``"Left"`` or ``"Right"``.
    ankle, toe:
        The foot joint and its toe joint (``-1`` when the character has none).
    joints, weights:
        ``(P, K)`` the joints each point is bound to and their weights (rows sum to 1).
    local:
        ``(P, K, 3)`` each point in the rest frame of each of its joints (character units).
    on_toe:
        ``(P,)`` the point moves mostly with the toe (more than half its weight below the foot; a
        vertex shared half and half across the ball moves with the foot).
    rest:
        ``(P, 3)`` the points in the rest pose (character units).
    across, toe_across:
        ``(3,)`` the foot's axis across it (``up x forward``, forward from the ankle to the sole's
        middle in the rest pose) in the foot joint's and in the toe joint's own frames: the axis
        the foot pitches and the toes roll about, turning with them (a direction from the ankle
        to the sole flips as the foot points down; this does not).
    guard:
        Points that move partly with the foot (from :data:`GUARD_SHARE` to half their weight in
        its subtree: a heel vertex that automatic weights shared with the shin) and must not go
        under the floor, but do not stand on it (:meth:`around`); ``None`` for a bone sole.
    """

    side: str
    ankle: int
    toe: int
    joints: npt.NDArray[np.intp]
    weights: Array
    local: Array
    on_toe: npt.NDArray[np.bool_]
    rest: Array
    across: Array
    toe_across: Array
    guard: Sole | None = None

    def around(self, positions: Array, rotations: Array) -> Array:
        """``(F, P', 3)`` :meth:`positions` and those of :attr:`guard`'s points: every point of the
        foot that must stay above the floor."""
        here = self.positions(positions, rotations)
        if self.guard is None:
            return here
        return np.concatenate((here, self.guard.positions(positions, rotations)), axis=1)

    def across_world(self, rotations: Array, toe: bool = False) -> Array:
        """``(F, 3)`` the unit axis across the foot (or its toes) in the world, on the floor's
        plane, in each frame of ``rotations (F, J, 4)``."""
        joint, axis = (self.toe, self.toe_across) if toe else (self.ankle, self.across)
        turned = rot.rotate(rotations[:, joint], np.broadcast_to(axis, (rotations.shape[0], 3)))
        flat = turned * np.array([1.0, 0.0, 1.0])
        return np.asarray(flat / np.maximum(np.linalg.norm(flat, axis=-1, keepdims=True), 1e-300))

    @property
    def size(self) -> int:
        return int(self.joints.shape[0])

    def positions(self, positions: Array, rotations: Array) -> Array:
        """``(F, P, 3)`` the points in the world of a pose: ``positions (F, J, 3)`` and
        ``rotations (F, J, 4)`` the character's joints (its units, :meth:`Motion.fk`)."""
        out = np.zeros((positions.shape[0], self.size, 3))
        for k in range(self.joints.shape[1]):
            w = self.weights[:, k]
            used = np.flatnonzero(w > 0)
            if used.size == 0:
                continue
            j = self.joints[used, k]
            loc = np.broadcast_to(self.local[used, k], (positions.shape[0], used.size, 3))
            out[:, used] += w[used, None] * (positions[:, j] + rot.rotate(rotations[:, j], loc))
        return out


def _subtree(parents: npt.NDArray[np.intp], top: int) -> npt.NDArray[np.bool_]:
    inside = np.zeros(parents.size, dtype=bool)
    inside[top] = True
    for j in range(top + 1, parents.size):
        if parents[j] >= 0 and inside[parents[j]]:
            inside[j] = True
    return inside


def _bound(
    points: Array, joints: npt.NDArray[np.intp], weights: Array, rest: Pose
) -> tuple[npt.NDArray[np.intp], Array, Array]:
    """Influences of ``points (P, 3)`` (rest pose, character units) compacted to the used joints,
    and their coordinates in each joint's rest frame."""
    order = np.argsort(-weights, axis=1, kind="stable")
    j = np.take_along_axis(joints, order, axis=1)
    w = np.take_along_axis(weights, order, axis=1)
    width = max(int((w > _MIN_WEIGHT).sum(axis=1).max(initial=1)), 1)
    j, w = j[:, :width], np.where(w[:, :width] > _MIN_WEIGHT, w[:, :width], 0.0)
    w = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    g = rest.rotations[0][j]  # (P, K, 4)
    local = rot.rotate(rot.inverse(g), points[:, None, :] - rest.positions[0][j])
    return j.astype(np.intp), w, np.asarray(local)


def _across(rest: Pose, ankle: int, toe: int, points: Array) -> tuple[Array, Array]:
    """The foot's axis across it (:attr:`Sole.across`) in the foot's and the toe's rest frames."""
    ahead = (points.mean(axis=0) - rest.positions[0, ankle]) * np.array([1.0, 0.0, 1.0])
    if np.linalg.norm(ahead) < 1e-12:
        ahead = rot.rotate(rest.rotations[0, ankle], np.array([0.0, 0.0, 1.0])) * np.array([1.0, 0.0, 1.0])
    axis = np.cross(np.array([0.0, 1.0, 0.0]), ahead / max(float(np.linalg.norm(ahead)), 1e-300))
    foot = rot.rotate(rot.inverse(rest.rotations[0, ankle]), axis)
    toes = rot.rotate(rot.inverse(rest.rotations[0, toe]), axis) if toe >= 0 else foot
    return np.asarray(foot), np.asarray(toes)


def _hull_corners(points: Array) -> npt.NDArray[np.intp]:
    """Indices of the corners of the convex hull of ``points (N, 3)`` (all of them when they are
    too few or flat for a hull)."""
    if points.shape[0] <= 8:
        return np.arange(points.shape[0])
    from scipy.spatial import ConvexHull, QhullError

    try:
        return np.asarray(np.sort(ConvexHull(points).vertices), dtype=np.intp)
    except (QhullError, ValueError):
        return np.arange(points.shape[0])


def _mesh_points(
    m: BoundMesh, placed: Array, below: npt.NDArray[np.bool_], rest: Pose, chosen: npt.NDArray[np.intp]
) -> tuple[npt.NDArray[np.intp], Array, Array, npt.NDArray[np.bool_], Array]:
    """The mesh vertices ``chosen`` (``placed``: in the rest pose) as a sole's points: ``joints``,
    ``weights`` and ``local`` bound as the skin binds them, ``on_toe`` (more than half their weight
    under the ankle: ``below``) and ``rest``."""
    joints, weights, local = _bound(placed[chosen], m.joints[chosen], m.weights[chosen], rest)
    toe_part = np.where(below[m.joints[chosen]], m.weights[chosen], 0.0).sum(axis=1) > 0.5 + 1e-6
    return joints, weights, local, toe_part, placed[chosen]


def mesh_soles(mesh: BoundMesh, character: Motion, roles: dict[str, int]) -> tuple[Sole, ...]:
    """Each foot's sole from the character's skinned mesh (module docstring), ``character`` in
    its rest pose (frame 0, the skin's joints, metres) and ``roles`` its role -> joint index.

    Raises :class:`MotionError` when a foot has no vertex weighted to it."""
    m = mesh.reindexed(character.skeleton.names)
    first = character.slice(0, 1)
    rest = Pose.of(first)
    scale = 1.0 / character.metres_per_unit  # the mesh is in metres, the character in its units
    # every vertex in the rest pose of the character (the nodes' pose, which may differ from the
    # bind pose a little): skinned by the character's rest pose
    from ..skinning import skin

    placed = skin(m, rest.positions * character.metres_per_unit, rest.rotations)[0] * scale
    parents = character.skeleton.parents
    out = []
    for side in SIDES:
        ankle = roles[f"{side}Foot"]
        toe = roles.get(f"{side}Toes", -1)
        foot = _subtree(parents, ankle)
        below = foot.copy()
        below[ankle] = False
        share = np.where(foot[m.joints], m.weights, 0.0).sum(axis=1)
        on = share >= 0.5
        if not on.any():
            raise MotionError(
                f"the character's mesh has no vertex weighted to its {side.lower()} foot "
                f"({character.skeleton.names[ankle]!r})"
            )
        idx = np.flatnonzero(on)
        toe_share = np.where(below[m.joints[idx]], m.weights[idx], 0.0).sum(axis=1)
        on_toe = toe_share > 0.5 + 1e-6
        keep = []
        for part in (~on_toe, on_toe):
            sel = idx[part]
            if sel.size:
                keep.append(sel[_hull_corners(placed[sel])])
        chosen = np.concatenate(keep)
        across = _across(rest, ankle, toe, placed[chosen])
        shared = np.flatnonzero((share >= GUARD_SHARE) & ~on)
        guard = None
        if shared.size:
            corners = shared[_hull_corners(placed[shared])]
            guard = Sole(side, ankle, toe, *_mesh_points(m, placed, below, rest, corners), *across)
        out.append(
            Sole(side, ankle, toe, *_mesh_points(m, placed, below, rest, chosen), *across, guard=guard)
        )
    return tuple(out)


def bone_soles(character: Motion, roles: dict[str, int]) -> tuple[Sole, ...]:
    """Each foot's sole from the character's bones (module docstring), ``character`` in its rest
    pose (frame 0, any units)."""
    first = character.slice(0, 1)
    rest = Pose.of(first)
    tips = tip_positions(first, rest)
    p = rest.positions[0]
    up = np.array([0.0, 1.0, 0.0])
    out = []
    for side in SIDES:
        ankle = roles[f"{side}Foot"]
        toe = roles.get(f"{side}Toes", -1)
        tip = tips[0, toe if toe >= 0 else ankle]
        # the foot's own lowest joint or tip: a rest pose taken from a clip may lift one foot
        floor = float(min(p[ankle, 1], tip[1], p[toe, 1] if toe >= 0 else np.inf))
        ahead = (tip - p[ankle]) * [1.0, 0.0, 1.0]
        length = float(np.linalg.norm(ahead))
        if length < 1e-9:  # a foot with no length ahead of the ankle: a point under the ankle
            ahead, length = np.array([0.0, 0.0, 1.0]), 1e-9
        fwd = ahead / length
        lateral = np.cross(up, fwd)
        half = 0.5 * FOOT_WIDTH * length
        ground = np.array([1.0, 0.0, 1.0])
        heel = p[ankle] * ground - HEEL_BACK * length * fwd
        ball = p[toe] * ground if toe >= 0 else heel + BALL_AT * (length * (1 + HEEL_BACK)) * fwd
        end = tip * ground
        w = half * lateral
        pts = np.array([heel + w, heel - w, ball + w, ball - w, end + 0.6 * w, end - 0.6 * w])
        pts[:, 1] = floor
        on_toe = np.array([False, False, False, False, toe >= 0, toe >= 0])
        bone = np.where(on_toe, toe, ankle).astype(np.intp)[:, None]
        joints, weights, local = _bound(pts, bone, np.ones((6, 1)), rest)
        out.append(
            Sole(side, ankle, toe, joints, weights, local, on_toe, pts, *_across(rest, ankle, toe, pts))
        )
    return tuple(out)


def soles_floor(soles: tuple[Sole, ...]) -> float:
    """The floor of the rest pose: the lowest point of the soles (character units)."""
    return float(min(s.rest[:, 1].min() for s in soles))
