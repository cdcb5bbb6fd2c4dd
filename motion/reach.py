"""Reaching: a hand (any joint two bones below its chain) brought to a point at one frame by
two-bone IK of its parent and grandparent (elbow and shoulder), faded in and out.

The graph engine uses it to make two characters' hands meet (:mod:`engines.graph.shared`): the
search and assembly's floor correction bring the bodies to the right place, but the height of a
hand at a frame (a phase of the arm swing) only follows from the clips chosen. The solver is the
foot-skate cleanup's closed-form two-bone IK (:func:`motion.footskate._solve_leg`, the same law
of cosines and soft reach near full extension, so an arm never snaps straight), run on the arm
instead of the leg; only the shoulder and elbow rotations change (the hand keeps its global
orientation and bone lengths are exact).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from .errors import MotionError
from .footskate import Leg, _forward, _solve_leg
from .motion import Motion

Array = npt.NDArray[np.float64]


def _arm(motion: Motion, joint: int) -> Leg:
    """The two-bone chain above ``joint`` (shoulder, elbow, the joint)."""
    sk = motion.skeleton
    elbow = int(sk.parents[joint])
    shoulder = int(sk.parents[elbow]) if elbow >= 0 else -1
    if shoulder < 0 or int(sk.parents[shoulder]) < 0:
        raise MotionError(f"joint {sk.names[joint]!r} has no shoulder and elbow above it to reach with")
    return Leg(hip=shoulder, knee=elbow, ankle=joint, toe=-1, ankle_slot=-1, toe_slot=-1)


def reach_path(motion: Motion, joint: int, offsets: Array) -> Motion:
    """``motion`` with joint ``joint`` moved by ``offsets (F, 3)`` metres in every frame (zero rows
    untouched) by arm IK (module docstring); what is beyond the arm's reach is left."""
    arm = _arm(motion, joint)
    offsets = np.asarray(offsets, dtype=np.float64)
    if offsets.shape != (motion.num_frames, 3):
        raise MotionError(f"{offsets.shape[0]} offsets for a motion of {motion.num_frames} frames")
    frames = np.flatnonzero(np.abs(offsets).max(axis=1) > 0)
    if frames.size == 0:
        return motion
    pos, grot = motion.fk()
    local = np.array(motion.rotations, copy=True)
    target = pos[frames, joint] + offsets[frames] / motion.metres_per_unit
    _solve_leg(arm, motion.skeleton, pos, grot, local, frames, target, None, None, -_forward(motion, pos))
    return replace(motion, rotations=local)


def reach(motion: Motion, joint: int, frame: int, target: Array, window: int) -> tuple[Motion, float]:
    """``motion`` with joint ``joint`` at ``target (3,)`` (metres) at ``frame``: the offset
    ``target - position`` is added to the joint's path with a smoothstep weight, 1 at ``frame``,
    0 at ``window`` frames either side, and each frame is solved by arm IK (module docstring).

    Returns the motion and the distance (metres) left at ``frame`` (beyond the arm's reach).
    Raises :class:`~motion.errors.MotionError` when the joint has no two bones above it."""
    arm = _arm(motion, joint)
    sk = motion.skeleton
    n = motion.num_frames
    if not 0 <= frame < n:
        raise MotionError(f"frame {frame} is outside the motion's {n} frames")
    pos, grot = motion.fk()
    mpu = motion.metres_per_unit
    delta = np.asarray(target, dtype=np.float64) / mpu - pos[frame, joint]
    frames = np.arange(max(frame - window, 0), min(frame + window + 1, n))
    x = 1.0 - np.abs(frames - frame) / (window + 1.0)
    w = x * x * (3.0 - 2.0 * x)
    local = np.array(motion.rotations, copy=True)
    # an arm bends the other way from a leg when it is straight: the forearm swings forward
    forward = -_forward(motion, pos)
    reached, _ = _solve_leg(
        arm, sk, pos, grot, local, frames, pos[frames, joint] + w[:, None] * delta, None, None, forward
    )
    at = int(np.flatnonzero(frames == frame)[0])
    left = float(np.linalg.norm(pos[frame, joint] + delta - reached[at])) * mpu
    return replace(motion, rotations=local), left
