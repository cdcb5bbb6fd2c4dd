"""Planted feet and the floor after a rotation transfer: two-bone leg IK on the contact frames.

A character with other proportions than the source slides its feet where the source's stood
(the root path is scaled by leg length, the feet follow the character's own bone lengths) and can
dip a toe under its floor. The contacts are detected on the transferred motion by
:func:`motion.contacts.detect_contacts` (the detector the quality report uses), on the
character's ankle and toe joints; :func:`motion.footskate.solve_foot_skate` then pins every contact
run and lifts any ankle or toe below its floor height.

Before that, :func:`settle` moves the whole body up or down (no limb turns) so that the flat
planted feet (ankle and toe both in contact) sit at the character's own rest ankle height: with
the feet turned flat by :func:`motion.retarget.transfer.planted_feet`, sole and toe are then on
the floor. The floor of each ankle (toe) is the lower of the two rest-pose ankles (toes), where a
flat foot has them; a rest pose taken from a clip may stand on one foot (hence the lower of the
two), and a rest pose that does not stand (lying down) is not used: then the floor is the lower of
the two ankles' (toes') usual lowest height in the transferred motion (5th percentile over frames,
the level the contact detector measures from).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..contacts import detect_contacts
from ..motion import Motion
from ..skinning import BoundMesh
from .grounding import ground_feet
from .sole import Sole, bone_soles, mesh_soles, soles_floor
from .transfer import place_hips

FOOT_ROLES = ("LeftFoot", "LeftToes", "RightFoot", "RightToes")
FLOOR_PERCENTILE = 5.0


def foot_groups_of(roles: dict[str, int]) -> list[tuple[int, ...]]:
    """The character's feet as :func:`motion.contacts.foot_plants` and the contact events take
    them: per side, the ankle then the toe (when it has one), by role (a role map's names count)."""
    return [
        tuple(roles[side + part] for part in ("Foot", "Toes") if side + part in roles)
        for side in ("Left", "Right")
        if side + "Foot" in roles
    ]


def foot_joints(roles: dict[str, int]) -> npt.NDArray[np.intp]:
    """The character's ankle and toe joints (those it has), ``(K,)``."""
    return np.array([roles[r] for r in FOOT_ROLES if r in roles], dtype=np.intp)


def floor_heights(roles: dict[str, int], positions: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``(K,)`` the floor of each of :func:`foot_joints`: the lower of its left and right
    counterparts' 5th-percentile heights over ``positions (F, J, 3)`` (the character's units)."""
    usual = np.percentile(positions[:, :, 1], FLOOR_PERCENTILE, axis=0)
    out = []
    for role in FOOT_ROLES:
        if role in roles:
            part = role.removeprefix("Left").removeprefix("Right")
            out.append(min(float(usual[roles[s + part]]) for s in ("Left", "Right") if s + part in roles))
    return np.array(out)


def rest_ankle_height(rest: Motion, roles: dict[str, int]) -> float | None:
    """The height of the lower ankle in the character's rest pose (frame 0 of ``rest``), where a
    planted ankle sits with the character's own sole and toe on the floor; ``None`` when that
    pose does not stand (hips less than half a leg above the lower ankle: a pose lying down)."""
    p = rest.global_positions()[0]
    ankle = min(float(p[roles[r], 1]) for r in ("LeftFoot", "RightFoot"))
    hip, knee, foot = (p[roles[f"Left{x}"]] for x in ("UpperLeg", "LowerLeg", "Foot"))
    leg = float(np.linalg.norm(knee - hip) + np.linalg.norm(foot - knee))
    return None if p[roles["Hips"], 1] - ankle < 0.5 * leg else ankle


def rest_floor(rest: Motion, roles: dict[str, int]) -> npt.NDArray[np.float64] | None:
    """``(K,)`` for :func:`foot_joints`, the lower of the left and right rest-pose heights of each
    (ankles, toes): where they are with the foot flat on the floor; ``None`` when the rest pose
    does not stand (:func:`rest_ankle_height`)."""
    if rest_ankle_height(rest, roles) is None:
        return None
    return floor_heights(roles, rest.global_positions())


def settle(
    motion: Motion,
    roles: dict[str, int],
    rest: Motion,
    soles: tuple[Sole, ...] | None = None,
    floor: float | None = None,
) -> Motion:
    """``motion`` moved up or down so that its flat planted feet sit, over the clip, on the
    floor: the median ankle height over the frames where an ankle and its toe (when the skeleton
    has toes) are both planted is the rest pose's (:func:`rest_ankle_height`), or with ``soles``
    and their ``floor`` the median lowest sole point on those frames is the floor. A vertical
    shift of the whole body: no limb turns. Unchanged when the rest pose does not stand or no
    foot is planted."""
    target = rest_ankle_height(rest, roles)
    if target is None:
        return motion
    pos = np.ascontiguousarray(motion.global_positions())
    by_side = {s.side: s for s in soles or ()}
    lowest = None
    if soles is not None and floor is not None:
        _, grot = motion.fk()
        lowest = {s.side: s.positions(pos, grot)[:, :, 1].min(axis=1) for s in soles}
    heights = []
    for side in ("Left", "Right"):
        joints = np.array([roles[side + p] for p in ("Foot", "Toes") if side + p in roles], dtype=np.intp)
        _, flags = detect_contacts(motion, joints, positions=pos)
        flat = flags.all(axis=1)
        if lowest is not None and side in by_side and floor is not None:
            heights.append(lowest[side][flat] - floor)
        else:
            heights.append(pos[flat, joints[0], 1] - target)
    flat_heights = np.concatenate(heights)
    if flat_heights.size == 0:
        return motion
    shift = float(np.median(flat_heights))
    hips = roles["Hips"]
    return place_hips(motion, hips, pos[:, hips] - np.array([0.0, shift, 0.0]))


def character_soles(rest: Motion, roles: dict[str, int], mesh: BoundMesh | None = None) -> tuple[Sole, ...]:
    """The character's soles (:mod:`motion.retarget.sole`): from its skinned mesh when it has one,
    else from its bones."""
    return mesh_soles(mesh, rest, roles) if mesh is not None else bone_soles(rest, roles)


def sole_floor(motion: Motion, soles: tuple[Sole, ...], rest: Motion, roles: dict[str, int]) -> float:
    """The floor the soles stand on: the rest pose's lowest sole point when that pose stands
    (:func:`rest_ankle_height`), else the usual lowest level of the soles in ``motion`` (the 5th
    percentile over frames of the lower sole's lowest point)."""
    if rest_ankle_height(rest, roles) is not None:
        return soles_floor(soles)
    pos, grot = motion.fk()
    low = np.min([s.positions(pos, grot)[:, :, 1].min(axis=1) for s in soles], axis=0)
    return float(np.percentile(low, FLOOR_PERCENTILE))


def plant_feet(
    motion: Motion,
    roles: dict[str, int],
    rest: Motion | None = None,
    *,
    soles: tuple[Sole, ...] | None = None,
    mode: str = "lock",
) -> Motion:
    """``motion`` with planted feet pinned (``mode="lock"``) and its soles on the floor
    (:func:`motion.retarget.grounding.ground_feet`).

    Parameters
    ----------
    motion:
        The transferred motion of the character (its units, Y up).
    roles:
        Role -> joint index of the character (:class:`motion.retarget.names.Correspondence`).
    rest:
        The character in its rest pose (default: ``motion``'s first frame): its soles and floor.
    soles:
        The character's soles (default: from its bones, :func:`character_soles`).
    mode:
        ``"lock"``, ``"grounding"`` or ``"free"`` (:data:`motion.retarget.grounding.FEET_MODES`).
    """
    rest = motion.slice(0, 1) if rest is None else rest
    soles = character_soles(rest, roles) if soles is None else soles
    floor = sole_floor(motion, soles, rest, roles)
    return ground_feet(motion, soles, floor, mode=mode)


def feet_on_floor(motion: Motion, mode: str) -> Motion:
    """A motion's own feet (not retargeted) kept on its floor (:func:`motion.retarget.grounding.ground_feet`):
    ``"lock"`` holds planted feet in place and keeps soles on the floor, ``"grounding"`` keeps
    soles on the floor only, ``"free"`` returns ``motion`` as it is. Its roles are found by name
    (:func:`motion.retarget.names.detect_roles`); its soles are made from its bones in a standing
    pose (its zero pose when that stands, else its first frame); its floor is the soles' usual
    lowest level (the 5th percentile over frames of the lower sole's lowest point). A combined
    motion of several characters (a crowd) has each character's feet kept on its floor.

    Raises :class:`MotionError` naming the missing joints when the skeleton's hips, legs and feet
    are not found under any naming convention."""
    from ..errors import MotionError
    from ..export.characters import combine_characters, split_characters, without_prefix
    from .names import REQUIRED, detect_roles, role_label
    from .transfer import zero_pose

    if mode == "free" or motion.num_frames < 2:
        return motion
    chars = split_characters(motion)
    if chars is not None:
        done = []
        for c in chars:
            plain, pre = without_prefix(c)
            moved = feet_on_floor(plain, mode)
            kept = Motion(
                c.skeleton,
                moved.root_positions,
                moved.rotations,
                c.fps,
                moved.joint_translations,
                c.units,
                c.name,
            )
            done.append((kept, pre))
        return combine_characters([m for m, _ in done], [p for _, p in done])
    roles = detect_roles(motion.skeleton).joints
    missing = [r for r in REQUIRED if r not in roles]
    if missing:
        raise MotionError(
            "cannot keep the feet on the floor: no joint found for "
            f"{', '.join(role_label(r) for r in missing)} (joint names of a known convention are "
            "needed; --feet free leaves the motion as it is)"
        )
    zero = zero_pose(motion)
    rest = zero if rest_ankle_height(zero, roles) is not None else motion.slice(0, 1)
    soles = bone_soles(rest, roles)
    pos, grot = motion.fk()
    low = np.min([s.positions(pos, grot)[:, :, 1].min(axis=1) for s in soles], axis=0)
    floor = float(np.percentile(low, FLOOR_PERCENTILE))
    return ground_feet(motion, soles, floor, mode=mode)
