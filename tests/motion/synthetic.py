"""Small synthetic motions for tests (no files needed)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from motion import Motion, Skeleton
from motion import rotations as rot
from motion.skeleton import default_channels

# A tiny biped: hips with two legs (thigh, shin, foot) and a spine with two arms.
BIPED_NAMES = (
    "hips", "lThigh", "lShin", "lFoot", "rThigh", "rShin", "rFoot",
    "spine", "head", "lShoulder", "lHand", "rShoulder", "rHand",
)  # fmt: skip
BIPED_PARENTS = np.array([-1, 0, 1, 2, 0, 4, 5, 0, 7, 7, 9, 7, 11])
BIPED_OFFSETS = np.array(
    [
        [0.0, 0.9, 0.0],
        [0.1, 0.0, 0.0], [0.0, -0.45, 0.0], [0.0, -0.4, 0.05],
        [-0.1, 0.0, 0.0], [0.0, -0.45, 0.0], [0.0, -0.4, 0.05],
        [0.0, 0.3, 0.0], [0.0, 0.4, 0.0],
        [0.2, 0.2, 0.0], [0.5, 0.0, 0.0],
        [-0.2, 0.2, 0.0], [-0.5, 0.0, 0.0],
    ]
)  # fmt: skip


def biped_skeleton() -> Skeleton:
    return Skeleton(
        BIPED_NAMES,
        BIPED_PARENTS,
        BIPED_OFFSETS,
        default_channels(len(BIPED_NAMES)),
        np.array([3, 6, 8]),
        np.array([[0.0, 0.0, 0.1], [0.0, 0.0, 0.1], [0.0, 0.15, 0.0]]),
    )


def walking_biped(
    frames: int = 120,
    fps: float = 30.0,
    speed: float = 1.2,
    heading_deg: float = 0.0,
    seed: int = 0,
    noise: float = 0.02,
) -> Motion:
    """A biped walking in a straight line along ``heading_deg`` at ``speed`` m/s, swinging its legs,
    with a little random rotation noise so nothing is degenerate."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / fps
    yaw = np.radians(heading_deg)
    direction = np.array([np.sin(yaw), 0.0, np.cos(yaw)])
    root = np.array([0.3, 0.9, -0.2]) + speed * t[:, None] * direction
    root[:, 1] += 0.02 * np.sin(4 * np.pi * t)
    q = rot.identity((frames, len(BIPED_NAMES)))
    q[:, 0] = rot.from_yaw(np.full(frames, yaw))
    swing = 0.4 * np.sin(2 * np.pi * t)
    q[:, 1] = rot.from_axis_angle(np.array([1.0, 0, 0]), swing)
    q[:, 4] = rot.from_axis_angle(np.array([1.0, 0, 0]), -swing)
    q[:, 2] = rot.from_axis_angle(np.array([1.0, 0, 0]), 0.3 + 0.3 * np.sin(2 * np.pi * t + 1))
    q[:, 5] = rot.from_axis_angle(np.array([1.0, 0, 0]), 0.3 - 0.3 * np.sin(2 * np.pi * t + 1))
    noise = rot.exp(rng.normal(scale=noise, size=(frames, len(BIPED_NAMES) - 7, 3)))
    q[:, 7:] = rot.multiply(q[:, 7:], noise)
    return Motion(biped_skeleton(), root, q, fps, units="m", name="walking-biped")


def rerigged(m: Motion, frame: np.ndarray) -> Motion:
    """The same motion on a rig whose every joint frame is turned by ``frame`` (a quaternion):
    local rotations ``F^-1 L F`` (the root's ``L F``), offsets ``F^-1 o``, the same positions. With
    a quarter turn about z the legs' bones run along a local x axis, as Bandai-Namco's do."""
    sk = m.skeleton
    f = np.broadcast_to(frame, m.rotations.shape)
    q = rot.multiply(rot.conjugate(f), rot.multiply(m.rotations, f))
    q[:, 0] = rot.multiply(m.rotations[:, 0], f[:, 0])
    offsets = sk.offsets.copy()
    offsets[1:] = rot.rotate(rot.conjugate(np.broadcast_to(frame, (sk.num_joints - 1, 4))), sk.offsets[1:])
    es = rot.rotate(
        rot.conjugate(np.broadcast_to(frame, sk.end_site_offsets.shape[:-1] + (4,))), sk.end_site_offsets
    )
    new_sk = replace(sk, offsets=offsets, end_site_offsets=es)
    return replace(m, skeleton=new_sk, rotations=q)
