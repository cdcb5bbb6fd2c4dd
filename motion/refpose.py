"""Reference-pose frames at the start of a clip: recognised, and dropped.

CMU's Daz conversions (and other retargeted captures) start with the skeleton's reference pose
(a T-pose: every joint at its zero rotation) and blend from it into the capture over the first
frames: ``sample:walk`` (120 fps) spends 4 frames on it, its hand moving 0.2 m per 1/120 s; the
30 fps conversions spend one. Played, exported or retargeted, those frames are a jerk out of a
T-pose.

A clip has such a lead when its first frame is a reference pose (:data:`REFERENCE_SHARE` of its
non-root joints within :data:`REFERENCE_DEG` of their zero rotation) and it leaves that pose at a
speed no body reaches (a joint faster than :data:`LEAD_SPEED_FACTOR` times the clip's median
largest joint speed, and at least :data:`LEAD_MIN_SPEED_MS`). The lead is every frame up to the
first one from which the joints move at that clip's usual speeds, at most :data:`LEAD_MAX_S`.
"""

from __future__ import annotations

import numpy as np

from .motion import Motion

REFERENCE_DEG = 10.0
"""A joint is in its reference pose within this angle (degrees) of its zero rotation..."""
REFERENCE_SHARE = 0.8
"""... and a frame is the reference pose when this share of the non-root joints are."""
LEAD_SPEED_FACTOR = 3.0
"""A blend out of the reference pose moves a joint this many times faster than the clip's median
largest joint speed..."""
LEAD_MIN_SPEED_MS = 6.0
"""... and faster than this (metres per second)."""
LEAD_MAX_S = 0.5
"""A lead is at most this long (seconds)."""


def reference_lead(motion: Motion) -> int:
    """The number of frames at the start of ``motion`` that are its reference pose and the blend
    out of it (module docstring); 0 when the clip does not start in its reference pose."""
    n = motion.num_frames
    if n < 3 or motion.num_joints < 2:
        return 0
    w = np.clip(np.abs(motion.rotations[0, 1:, 3]), 0.0, 1.0)
    angle = np.degrees(2.0 * np.arccos(w))
    if np.mean(angle < REFERENCE_DEG) < REFERENCE_SHARE:
        return 0
    pos = motion.global_positions() * motion.metres_per_unit
    speed = np.linalg.norm(np.diff(pos, axis=0), axis=-1).max(axis=1) * motion.fps  # (F-1,)
    limit = max(LEAD_SPEED_FACTOR * float(np.median(speed)), LEAD_MIN_SPEED_MS)
    longest = max(1, int(LEAD_MAX_S * motion.fps))
    fast = speed[:longest] > limit
    if not fast[0]:
        return 0
    lead = int(np.flatnonzero(fast)[-1]) + 1  # frames before the first step at usual speeds
    return lead if lead < n - 1 else 0


def without_reference_lead(motion: Motion) -> tuple[Motion, int]:
    """``motion`` from its first frame past the reference-pose lead, and how many were dropped."""
    lead = reference_lead(motion)
    return (motion.slice(lead, None) if lead else motion), lead
