"""Pose features in the body's own ground frame (translation and heading removed).

Used by the engines for frame-to-frame comparisons: joint positions and velocities expressed in
each frame's torso/ground frame (see :mod:`motion.ground`), plus the torso's own velocity,
acceleration and turning rate, so that two frames compare equal whatever their place on the floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .errors import MotionError
from .ground import body_root, ground_frames, to_ground_frame
from .motion import Motion

Array = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class TorsoFeatures:
    """Per-frame features in the ground frame; lengths in metres, times in seconds.

    Attributes
    ----------
    joints: ``(K,)`` joint indices the arrays refer to.
    positions: ``(F, K, 3)`` joint positions in each frame's ground frame (origin on the floor
        under the root, +Z forward, +X to the body's left, Y up).
    velocities: ``(F, K, 3)`` m/s, world velocities rotated into the frame's ground frame.
    root_velocity: ``(F, 3)`` m/s, the root's velocity in its ground frame.
    root_acceleration: ``(F, 3)`` m/s^2, likewise.
    turn_rate: ``(F,)`` rad/s, derivative of the heading.
    """

    joints: npt.NDArray[np.intp]
    positions: Array
    velocities: Array
    root_velocity: Array
    root_acceleration: Array
    turn_rate: Array

    def stacked(self, velocity_weight: float = 1.0) -> Array:
        """``(F, K*6 + 7)`` one row per frame: positions, weighted velocities, root terms."""
        f = self.positions.shape[0]
        return np.concatenate(
            (
                self.positions.reshape(f, -1),
                velocity_weight * self.velocities.reshape(f, -1),
                velocity_weight * self.root_velocity,
                velocity_weight * self.root_acceleration,
                velocity_weight * self.turn_rate[:, None],
            ),
            axis=1,
        )


def _derivative(x: Array, fps: float) -> Array:
    """Central differences along axis 0 (one-sided at the ends), per second."""
    if x.shape[0] < 2:
        return np.zeros_like(x)
    return np.asarray(np.gradient(x, 1.0 / fps, axis=0))


def torso_features(
    motion: Motion, joints: list[str] | npt.NDArray[np.intp] | None = None, positions: Array | None = None
) -> TorsoFeatures:
    """Joint positions and velocities in the ground frame, and the torso's own motion.

    Parameters
    ----------
    motion:
        The motion (its units convert to metres; unknown units count as metres).
    joints:
        Joint names or indices (default: all joints).
    positions:
        Precomputed ``motion.global_positions()`` to avoid repeating FK.
    """
    sk = motion.skeleton
    if joints is None:
        idx = np.arange(sk.num_joints, dtype=np.intp)
    else:
        idx = np.array([sk.index(j) if isinstance(j, str) else int(j) for j in joints], dtype=np.intp)
        if idx.size == 0 or idx.min() < 0 or idx.max() >= sk.num_joints:
            raise MotionError("joints must name or index joints of the skeleton")
    scale = motion.metres_per_unit
    pos = (motion.global_positions() if positions is None else positions) * scale
    origin, yaw = ground_frames(motion, pos)
    local = to_ground_frame(pos[:, idx], origin, yaw)
    zero = np.zeros_like(origin)
    world_vel = _derivative(pos[:, idx], motion.fps)
    vel = to_ground_frame(world_vel, zero, yaw)
    root = pos[:, body_root(motion.skeleton)]
    root_vel_w = _derivative(root, motion.fps)
    root_acc_w = _derivative(root_vel_w, motion.fps)
    root_vel = to_ground_frame(root_vel_w[:, None], zero, yaw)[:, 0]
    root_acc = to_ground_frame(root_acc_w[:, None], zero, yaw)[:, 0]
    return TorsoFeatures(idx, local, vel, root_vel, root_acc, _derivative(yaw, motion.fps))
