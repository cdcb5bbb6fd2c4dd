"""Looping clips: make a motion's last pose the first one, so that it plays in a loop.

A game plays a clip over and over; it loops without a pop when the last frame's pose is the first
frame's pose. :func:`close_loop` corrects the end of a motion towards its first pose:

* every joint's local rotation is multiplied by a correction that grows from the identity to
  ``q[0] q[-1]^-1`` over the last ``blend_s`` seconds (a smoothstep ramp), so the last frame's
  rotation is exactly the first one's;
* the root joint and the body root (the hips, :func:`motion.ground.body_root`) keep their heading
  (rotation about +Y) and floor travel: only their tilt (the rotation left after the heading is
  taken off) and their height are corrected. Root travel continues, as the game's root motion
  does; the root-relative pose and the hip height return to the start.

A correction spread over a second or more moves each frame by a small fraction of the difference,
which keeps feet far steadier than cutting to the first pose would. The loop error is measured on
the output by :class:`motion.goals.LoopGoal` in the quality report.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .goals import LoopGoal
from .ground import body_root
from .motion import Motion
from .quality import QualityInputs

Array = npt.NDArray[np.float64]

LOOP_BLEND_S = 1.0
"""Default length (seconds) of the correction at the end of the clip."""


def loop_weights(num_frames: int, blend_frames: int) -> Array:
    """``(F,)`` correction weights: 0 before the last ``blend_frames`` frames, then a smoothstep
    ramp reaching exactly 1 on the last frame."""
    w = np.zeros(num_frames)
    n = int(min(max(blend_frames, 1), num_frames - 1))
    if n <= 0:
        return w
    x = np.arange(1, n + 1) / n
    w[num_frames - n :] = x * x * (3.0 - 2.0 * x)
    return w


def _split_heading(q: Array) -> tuple[Array, Array]:
    """``(F,)`` heading angles and ``(F, 4)`` tilts with ``q = yaw(h) * tilt``."""
    h = rot.yaw(q)
    return h, rot.multiply(rot.from_yaw(-h), q)


def close_loop(motion: Motion, blend_s: float = LOOP_BLEND_S) -> Motion:
    """The motion with its end corrected towards its first pose (module docstring).

    Parameters
    ----------
    motion:
        ``F`` frames; motions of fewer than 3 frames are returned unchanged.
    blend_s:
        Seconds over which the correction ramps in (at most the whole clip but its first frame).
    """
    f = motion.num_frames
    if f < 3:
        return motion
    w = loop_weights(f, int(round(blend_s * motion.fps)))
    sk = motion.skeleton
    roots = sorted({0, body_root(sk)})
    q = np.array(rot.normalize(motion.rotations), copy=True)
    others = np.setdiff1d(np.arange(sk.num_joints), roots)
    if others.size:
        d = rot.multiply(q[0, others], rot.conjugate(q[-1, others]))  # (J', 4)
        corr = rot.slerp(rot.identity((f, others.size)), np.broadcast_to(d, (f, *d.shape)), w[:, None])
        q[:, others] = rot.multiply(corr, q[:, others])
    for j in roots:
        h, tilt = _split_heading(q[:, j])
        d = rot.multiply(tilt[0], rot.conjugate(tilt[-1]))
        corr = rot.slerp(rot.identity((f,)), np.broadcast_to(d, (f, 4)), w)
        q[:, j] = rot.multiply(rot.from_yaw(h), rot.multiply(corr, tilt))
    root = np.array(motion.root_positions, copy=True)
    root[:, 1] += w * (root[0, 1] - root[-1, 1])
    jt = np.array(motion.joint_translations, copy=True)
    for k, j in enumerate(sk.translated_joints.tolist()):
        if j in roots:
            jt[:, k, 1] += w * (jt[0, k, 1] - jt[-1, k, 1])
        else:
            jt[:, k] += w[:, None] * (jt[0, k] - jt[-1, k])
    return Motion(sk, root, q, motion.fps, joint_translations=jt, units=motion.units, name=motion.name)


def with_loop_goal(inputs: QualityInputs) -> QualityInputs:
    """The quality inputs with the ``loop`` goal added (:class:`motion.goals.LoopGoal`)."""
    return replace(inputs, goals=(*inputs.goals, LoopGoal()))
