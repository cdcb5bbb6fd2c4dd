"""Planted feet stay planted and above the floor after retargeting onto other proportions."""

from __future__ import annotations

import numpy as np

from motion.contacts import detect_contacts
from motion.retarget import correspond, retarget
from motion.retarget.legik import FOOT_ROLES, floor_heights, foot_joints

from .characters import character, walk


def test_planted_feet_stay_planted_and_above_the_floor() -> None:
    src = walk(360)
    char = character("unreal", scale=0.9, shin=1.25)  # longer shins than the source's
    roles = correspond(src.skeleton, char.skeleton).target_roles
    joints = foot_joints(roles)
    raw = retarget(src, char, plant=False)
    out = retarget(src, char)
    raw_pos, pos = raw.global_positions(), out.global_positions()
    _, flags = detect_contacts(raw, joints, positions=raw_pos)
    planted = flags[1:] & flags[:-1]

    def slide(p: np.ndarray) -> float:
        v = np.linalg.norm(np.diff(p[:, joints][:, :, [0, 2]], axis=0), axis=-1) * out.fps
        return float(np.mean(v[planted]))

    m = out.metres_per_unit
    assert slide(pos) * m < 0.02, f"planted feet slide {slide(pos) * m:.3f} m/s"
    assert slide(pos) < 0.5 * slide(raw_pos)
    floor = floor_heights(roles, raw_pos)
    assert np.all(pos[:, joints, 1] >= floor - 1e-6 / m), "a foot goes under its floor"
    # the IK lifts and pins; it does not float the feet: the lowest foot stays as high as before
    lowest, lowest_raw = ((p[:, joints, 1] - floor).min(axis=1) for p in (pos, raw_pos))
    assert abs(np.median(lowest) - np.median(lowest_raw)) * m < 0.01
    assert [r for r in FOOT_ROLES if r in roles] == ["LeftFoot", "RightFoot"]  # CMU-Daz: no toes
