"""Planted feet and the floor after a rotation transfer: two-bone leg IK on the contact frames.

A character with other proportions than the source slides its feet where the source's stood
(the root path is scaled by leg length, the feet follow the character's own bone lengths) and can
dip a toe under its floor. The contacts are detected on the transferred motion by
:func:`motion.contacts.detect_contacts` (the detector the quality report uses), on the
character's ankle and toe joints; :func:`motion.footskate.solve_foot_skate` then pins every contact
run and lifts any ankle or toe below its floor height: the lower of the two ankles' (toes')
usual lowest height in the transferred motion (5th percentile over frames, the level the contact
detector measures from). The character's rest pose is not used for it: a rest pose taken from a
clip may stand on one foot, or on its heels.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..contacts import detect_contacts
from ..footskate import solve_foot_skate
from ..motion import Motion

FOOT_ROLES = ("LeftFoot", "LeftToes", "RightFoot", "RightToes")
FLOOR_PERCENTILE = 5.0


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


def plant_feet(motion: Motion, roles: dict[str, int]) -> Motion:
    """``motion`` with planted feet pinned and no ankle or toe under its floor.

    Parameters
    ----------
    motion:
        The transferred motion of the character (its units, Y up).
    roles:
        Role -> joint index of the character (:class:`motion.retarget.names.Correspondence`).
    """
    joints = foot_joints(roles)
    pos = np.ascontiguousarray(motion.global_positions())
    floor = floor_heights(roles, pos)
    joints, flags = detect_contacts(motion, joints, positions=pos)
    result = solve_foot_skate(motion, (joints, flags), blend_s=0.1, floor=floor)
    return result.motion
