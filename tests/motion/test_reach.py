"""Two-bone reaching (:mod:`motion.reach`): hands onto targets, bones kept, weights blend; on a real
walk a hand lands on its target at a frame, the rest of the body is untouched and the change fades."""

from __future__ import annotations

import numpy as np
import pytest

from motion.errors import MotionError
from motion.io import load_motion
from motion.reach import reach, reach_at, reach_path, smooth_weights
from motion.samples import sample_path
from tests.motion.synthetic import walking_biped


def test_a_hand_reaches_a_target_within_reach_and_bones_keep_their_length() -> None:
    m = walking_biped(20, seed=1)
    hand = m.skeleton.names.index("rHand")
    pos = m.global_positions()
    target = pos[:, hand] + np.array([0.05, 0.08, 0.04]) / m.metres_per_unit  # a few cm away
    weights = np.ones((20, 1))
    weights[:5] = 0.0
    out = reach(m, np.array([hand]), target[:, None], weights)
    got = out.global_positions()
    np.testing.assert_allclose(got[5:, hand], target[5:], atol=1e-6)
    np.testing.assert_allclose(got[:5], pos[:5], atol=1e-9)  # weight 0: unchanged
    parents = m.skeleton.parents
    bones = lambda p: np.linalg.norm(p[:, 1:] - p[:, parents[1:]], axis=-1)  # noqa: E731
    np.testing.assert_allclose(bones(got), bones(pos), atol=1e-9)
    # this skeleton has no elbow: the chain is spine -> rShoulder -> rHand; the legs do not move
    legs = [j for j in range(m.num_joints) if "Thigh" in m.skeleton.names[j] or "Shin" in m.skeleton.names[j]]
    np.testing.assert_allclose(got[:, legs], pos[:, legs], atol=1e-9)


def test_smooth_weights_ease_in_and_out() -> None:
    active = np.zeros(20, dtype=bool)
    active[8:12] = True
    w = smooth_weights(active, 3)
    assert (w[8:12] == 1).all() and w[0] == 0 and w[-1] == 0
    assert 0 < w[6] < w[7] < 1 and np.all(np.diff(w[:9]) >= 0)


def test_bad_shapes_are_refused() -> None:
    m = walking_biped(5)
    with pytest.raises(MotionError, match="targets must be"):
        reach(m, np.array([1]), np.zeros((4, 1, 3)), np.zeros((5, 1)))


def test_reach_brings_the_hand_to_its_target_and_fades() -> None:
    m = load_motion(sample_path("walk-05-01"))
    j = m.skeleton.index("rHand")
    p = m.global_positions() * m.metres_per_unit
    target = p[60, j] + np.array([0.05, 0.12, 0.08])
    out, left = reach_at(m, j, 60, target, 12)
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
    with pytest.raises(MotionError, match="no two-bone chain"):
        reach_at(m, m.skeleton.index("abdomen"), 10, np.zeros(3), 5)
    with pytest.raises(MotionError, match="outside"):
        reach_at(m, m.skeleton.index("rHand"), 10_000, np.zeros(3), 5)


def test_reach_path_moves_the_hand_by_its_offsets_and_leaves_zero_rows() -> None:
    m = load_motion(sample_path("walk-05-01")).slice(0, 40)
    j = m.skeleton.index("lHand")
    p = m.global_positions() * m.metres_per_unit
    offsets = np.zeros((40, 3))
    offsets[10:30] = [0.0, 0.05, 0.04]
    q = reach_path(m, j, offsets).global_positions() * m.metres_per_unit
    np.testing.assert_allclose(q[10:30, j], p[10:30, j] + offsets[10:30], atol=1e-6)
    np.testing.assert_allclose(q[:10], p[:10], atol=1e-9)
    assert reach_path(m, j, np.zeros((40, 3))) is m
    with pytest.raises(MotionError, match="offsets"):
        reach_path(m, j, np.zeros((5, 3)))
