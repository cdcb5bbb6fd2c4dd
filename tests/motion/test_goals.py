"""Goals of :mod:`motion.goals` measured on positions: the hand-hold goal."""

from __future__ import annotations

import numpy as np

from motion.goals import HandholdGoal, measure


def test_handhold_goal_counts_the_frames_whose_hands_meet() -> None:
    positions = np.zeros((10, 3, 3))  # (F, J, 3): joints 1 and 2 are the hands
    positions[:, 1] = [1.0, 1.0, 0.0]
    positions[:, 2] = [-1.0, 1.0, 0.0]
    partner = np.tile(np.array([[[1.1, 1.0, 0.0], [5.0, 1.0, 0.0]]]), (4, 1, 1))  # (4, H=2, 3)
    partner[3, 0] = [3.0, 1.0, 0.0]  # the last annotated frame: hands 2 m apart
    goal = HandholdGoal("handhold", np.array([2, 3, 4, 5]), np.array([1, 2]), partner, tolerance_cm=20.0)
    entry, reason = measure(goal, positions, 30.0, [])
    assert entry["frames"] == 4 and entry["held_fraction"] == 0.75
    assert entry["median_cm"] == 10.0 and not entry["satisfied"]
    assert reason is not None and "75%" in reason
    loose = HandholdGoal("handhold", np.array([2, 3, 4]), np.array([1, 2]), partner[:3])
    assert measure(loose, positions, 30.0, [])[1] is None
    # with a margin, the ends of each run of frames are not counted (joining, letting go)
    runs = HandholdGoal("handhold", np.array([2, 3, 4, 5]), np.array([1, 2]), partner, margin=1)
    kept, _ = measure(runs, positions, 30.0, [])
    assert kept["frames"] == 2 and kept["held_fraction"] == 1.0 and kept["satisfied"]
    # frames beyond the output are not counted
    beyond = HandholdGoal("handhold", np.array([20]), np.array([1]), partner[:1])
    assert measure(beyond, positions, 30.0, [])[0] == {"frames": 0, "satisfied": True}
