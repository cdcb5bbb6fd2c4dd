"""Arm reach (motion.reach) on a real walk: the hand lands on its target at the frame, the rest of
the body is untouched, bone lengths are kept and the change fades out."""

from __future__ import annotations

import numpy as np
import pytest

from motion import MotionError
from motion.io import load_motion
from motion.reach import reach
from motion.samples import sample_path


def test_reach_brings_the_hand_to_its_target_and_fades() -> None:
    m = load_motion(sample_path("walk-05-01"))
    j = m.skeleton.index("rHand")
    p = m.global_positions() * m.metres_per_unit
    target = p[60, j] + np.array([0.05, 0.12, 0.08])
    out, left = reach(m, j, 60, target, 12)
    q = out.global_positions() * out.metres_per_unit
    assert left < 1e-6 and np.linalg.norm(q[60, j] - target) < 1e-6
    moved = np.abs(q - p).max(axis=(1, 2))
    assert moved[:48].max() < 1e-9 and moved[73:].max() < 1e-9  # outside the window: untouched
    assert moved[48] < moved[54] < moved[60]  # faded in
    arm = [m.skeleton.index(n) for n in ("rShldr", "rForeArm", "rHand")]
    others = [
        i
        for i in range(m.num_joints)
        if (i not in arm and not m.skeleton.names[i].startswith("r")) or i < arm[0]
    ]
    np.testing.assert_allclose(q[:, m.skeleton.index("lHand")], p[:, m.skeleton.index("lHand")], atol=1e-9)
    np.testing.assert_allclose(q[:, m.skeleton.index("head")], p[:, m.skeleton.index("head")], atol=1e-9)
    assert others
    for a, b in ((arm[0], arm[1]), (arm[1], arm[2])):
        np.testing.assert_allclose(
            np.linalg.norm(q[:, a] - q[:, b], axis=1), np.linalg.norm(p[:, a] - p[:, b], axis=1), atol=1e-9
        )


def test_reach_needs_an_arm_and_a_frame_inside() -> None:
    m = load_motion(sample_path("walk-05-01"))
    with pytest.raises(MotionError, match="no shoulder and elbow"):
        reach(m, m.skeleton.index("abdomen"), 10, np.zeros(3), 5)
    with pytest.raises(MotionError, match="outside"):
        reach(m, m.skeleton.index("rHand"), 10_000, np.zeros(3), 5)
