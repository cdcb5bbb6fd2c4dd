"""Planted feet and the floor after a rotation transfer: two-bone leg IK on the contact frames.

A character with other proportions than the source slides its feet where the source's stood
(the root path is scaled by leg length, the feet follow the character's own bone lengths) and can
dip a toe under its floor. The contacts are detected on the transferred motion by
:func:`motion.contacts.detect_contacts` (the detector the quality report uses), on the
character's ankle and toe joints; :func:`motion.footskate.solve_foot_skate` then pins every contact
run and lifts any ankle or toe below its floor height, where the floor of a joint is its height
in the character's rest pose, standing (an ankle or a ball of the foot never goes lower than when
the foot is flat on the floor).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..contacts import detect_contacts
from ..footskate import solve_foot_skate
from ..motion import Motion

FOOT_ROLES = ("LeftFoot", "LeftToes", "RightFoot", "RightToes")


def foot_joints(roles: dict[str, int]) -> npt.NDArray[np.intp]:
    """The character's ankle and toe joints (those it has), ``(K,)``."""
    return np.array([roles[r] for r in FOOT_ROLES if r in roles], dtype=np.intp)


def plant_feet(motion: Motion, roles: dict[str, int], rest_heights: npt.NDArray[np.float64]) -> Motion:
    """``motion`` with planted feet pinned and no ankle or toe under its floor.

    Parameters
    ----------
    motion:
        The transferred motion of the character (its units, Y up).
    roles:
        Role -> joint index of the character (:class:`motion.retarget.names.Correspondence`).
    rest_heights:
        ``(J,)`` the height of every joint in the character's rest pose (its units).
    """
    joints = foot_joints(roles)
    joints, flags = detect_contacts(motion, joints)
    result = solve_foot_skate(motion, (joints, flags), blend_s=0.1, floor=rest_heights[joints])
    return result.motion
