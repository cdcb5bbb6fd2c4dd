"""Goals of :mod:`motion.goals` measured on positions: the hand-hold and foot-plant goals."""

from __future__ import annotations

import numpy as np

from motion.goals import FootplantGoal, HandholdGoal, measure, planted_speeds


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


def test_planted_speeds_take_whole_planted_intervals_of_the_step() -> None:
    fps = 120.0
    positions = np.zeros((13, 2, 3))  # joint 1 is the foot; it moves 1 cm per frame along +X
    positions[:, 1, 0] = 0.01 * np.arange(13)
    positions[:, 1, 1] = 5.0 * np.arange(13)  # vertical motion is not sliding
    contacts = np.zeros((13, 1), dtype=bool)
    contacts[0:9] = True  # planted over frames 0-8: intervals of 4 frames starting at 0..4
    speeds = planted_speeds(positions, np.array([1]), contacts, fps, 1.0 / 30.0)
    assert speeds.shape == (5,)
    np.testing.assert_allclose(speeds, 0.01 * fps)  # 1.2 m/s, measured over 4 frames
    assert planted_speeds(positions[:4], np.array([1]), contacts[:4], fps, 1.0 / 30.0).size == 0


def test_footplant_goal_compares_the_slide_with_its_tolerance() -> None:
    positions = np.zeros((31, 2, 3))
    positions[:, 1, 2] = 0.002 * np.arange(31)  # 0.06 m/s at 30 fps
    contacts = np.ones((31, 1), dtype=bool)
    entry, reason = measure(FootplantGoal("footplants", np.array([1]), contacts, 0.1), positions, 30.0, [])
    assert entry["frames"] == 30 and entry["slide_m_s"] == 0.06 and entry["satisfied"] and reason is None
    entry, reason = measure(FootplantGoal("footplants", np.array([1]), contacts, 0.05), positions, 30.0, [])
    assert not entry["satisfied"] and reason is not None and "0.06 m/s" in reason
    none = FootplantGoal("footplants", np.array([1]), np.zeros((31, 1), dtype=bool), 0.05)
    assert measure(none, positions, 30.0, []) == ({"frames": 0, "satisfied": True}, None)
