"""Two-bone reaching (:mod:`motion.reach`): hands onto targets, bones kept, weights blend."""

from __future__ import annotations

import numpy as np
import pytest

from motion.errors import MotionError
from motion.reach import reach, smooth_weights
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
