"""Looping clips: :func:`motion.looping.close_loop` and the quality report's ``loop`` goal."""

from __future__ import annotations

import numpy as np
import pytest

import motion
from motion.goals import LoopGoal, body_pose
from motion.ground import add_ground_root, ground_frames
from motion.looping import close_loop, loop_weights, with_loop_goal
from motion.quality import QualityInputs, assess
from motion.samples import sample_path

from .synthetic import walking_biped


def loop_entry(m: motion.Motion) -> dict[str, float]:
    report = assess(m, with_loop_goal(QualityInputs()))
    entry: dict[str, float] = report.constraint_errors["loop"]
    return entry


@pytest.mark.parametrize("ground", [False, True])
def test_closed_loop_ends_in_the_first_pose_and_keeps_travelling(ground: bool) -> None:
    m = motion.read_bvh(sample_path("walk-05-01")).to_units("m").slice(1, 101)  # frame 0: a T-pose
    if ground:
        m = add_ground_root(m)
    before = loop_entry(m)
    assert not before["satisfied"] and before["pose_cm"] > 10  # a walk's last step is not its first
    out = close_loop(m, blend_s=1.0)
    after = loop_entry(out)
    assert after["satisfied"] and after["pose_cm"] < 0.5, after
    pos, new = m.global_positions(), out.global_positions()
    np.testing.assert_allclose(new[:70], pos[:70], atol=1e-9)  # untouched before the last second
    xz, yaw = ground_frames(m, pos)
    xz2, yaw2 = ground_frames(out, new)
    assert np.linalg.norm(xz2[-1] - xz[-1]) < 0.05  # the root keeps travelling
    assert abs(yaw2[-1] - yaw[-1]) < np.radians(3)
    step = np.linalg.norm(np.diff(body_pose(new, out.skeleton), axis=0), axis=-1).max(axis=1)
    step0 = np.linalg.norm(np.diff(body_pose(pos, m.skeleton), axis=0), axis=-1).max(axis=1)
    assert (
        step[69:].max() < step0.max() + 0.03
    )  # no pop on the way: joints move as fast as before, +3 cm/frame


def test_loop_goal_reports_the_measured_gap() -> None:
    m = walking_biped(frames=40)
    entry = loop_entry(m)
    pose = body_pose(m.global_positions()[[0, 39]], m.skeleton)
    gap = 100 * np.linalg.norm(pose[1] - pose[0], axis=-1).max()
    assert entry["pose_cm"] == pytest.approx(gap, abs=1e-3)
    assert entry["satisfied"] == (gap <= LoopGoal().tolerance_cm)
    assert entry["first_frame"] == 0 and entry["last_frame"] == 39


def test_loop_weights_and_short_clips() -> None:
    w = loop_weights(10, 4)
    assert w[:6].tolist() == [0.0] * 6 and w[-1] == 1.0 and np.all(np.diff(w[5:]) > 0)
    m = walking_biped(frames=2)
    assert close_loop(m) is m
