"""Meeting floor goals within physical limits (motion.floorfit)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motion.errors import MotionError
from motion.floorfit import CorrectionLimits, FloorGoal, faded_shifts, floor_correction, water_fill
from tests.thoroughness import examples

FPS = 30.0


def straight(frames: int = 301, speed: float = 1.2) -> tuple[np.ndarray, np.ndarray]:
    """A body walking along +Z at ``speed`` m/s, facing +Z."""
    t = np.arange(frames) / FPS
    return np.stack((np.zeros(frames), speed * t), axis=-1), np.zeros(frames)


def corrected(xz: np.ndarray, theta: np.ndarray, shift: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.stack((c * xz[:, 0] + s * xz[:, 1], -s * xz[:, 0] + c * xz[:, 1]), axis=-1) + shift


@settings(max_examples=examples(200), deadline=None)
@given(
    st.lists(st.floats(0, 5, allow_nan=False), min_size=1, max_size=30),
    st.floats(0, 200, allow_nan=False),
)
def test_water_fill_is_capped_even_and_sums(caps: list[float], total: float) -> None:
    c = np.array(caps)
    share = water_fill(c, total)
    assert np.all(share >= -1e-12) and np.all(share <= c + 1e-9)
    assert share.sum() == pytest.approx(min(total, c.sum()), abs=1e-6)
    # as even as the caps allow: every frame below its cap gets the largest share
    free = share < c - 1e-9
    if free.any():
        assert np.all(share <= share[free].max() + 1e-9)


def test_reachable_goals_are_met_exactly_and_spread_evenly() -> None:
    xz, yaw = straight()
    goals = [FloorGoal(0, np.zeros(2), 0.0), FloorGoal(300, np.array([0.5, 12.5]), np.radians(10))]
    fix = floor_correction(xz, yaw, FPS, goals, CorrectionLimits(3.0, 6.0))
    out = corrected(xz, fix.theta, fix.shift)
    assert np.allclose(out[0], 0.0) and np.allclose(out[-1], [0.5, 12.5], atol=1e-9)
    assert np.degrees(fix.theta[-1]) == pytest.approx(10.0)
    assert np.all(fix.position_left < 1e-9) and np.all(fix.heading_left < 1e-9)
    speed = np.linalg.norm(np.diff(out, axis=0), axis=1) * FPS
    assert speed.max() < 1.2 * 1.15 + 0.05 + 1e-6  # at most 15 % + 5 cm/s added


def test_unreachable_goal_is_left_as_error_within_limits() -> None:
    xz, yaw = straight()
    limits = CorrectionLimits(speed_max=1.5, turn_max=6.0)
    goals = [FloorGoal(0, np.zeros(2), 0.0), FloorGoal(300, np.array([0.0, 85.0]))]
    fix = floor_correction(xz, yaw, FPS, goals, limits)
    out = corrected(xz, fix.theta, fix.shift)
    speed = np.linalg.norm(np.diff(out, axis=0), axis=1) * FPS
    assert speed.max() <= 1.5 + 1e-6  # never faster than the fastest example
    assert fix.position_left[1] == pytest.approx(85.0 - out[-1, 1], abs=1e-6)
    assert fix.position_left[1] > 70
    # the paper's rule (no limits) meets it by dragging the body at 8.5 m/s
    free = floor_correction(xz, yaw, FPS, goals, None)
    dragged = corrected(xz, free.theta, free.shift)
    assert (
        np.allclose(dragged[-1], [0, 85]) and np.linalg.norm(np.diff(dragged, axis=0), axis=1).max() * FPS > 8
    )


def test_offset_goals_aim_another_point_and_the_first_goal_is_rigid() -> None:
    """A joint 0.4 m to the body's left at frame 150 should be at (1, 6): the body goes to
    (0.6, 6) (its left is +X when it faces +Z). With no goal before it, the move is rigid."""
    xz, yaw = straight()
    goal = FloorGoal(150, np.array([1.0, 6.0]), None, offset=np.array([0.4, 0.0]))
    fix = floor_correction(xz, yaw, FPS, [goal], CorrectionLimits(3.0, 6.0))
    out = corrected(xz, fix.theta, fix.shift)
    assert np.allclose(out[150], [0.6, 6.0])
    assert np.allclose(np.diff(out, axis=0), np.diff(xz, axis=0))  # rigid: speeds unchanged


def test_faded_shifts_meet_each_goal_and_vanish_away_from_them() -> None:
    frames = np.array([0, 150, 180])
    residuals = np.array([[1.0, -0.5], [0.2, 0.0], [-0.3, 0.4]])
    shift = faded_shifts(frames, residuals, 300, 60)
    np.testing.assert_allclose(shift[frames], residuals, atol=1e-12)  # overlapping bumps solved together
    np.testing.assert_array_equal(shift[240:], 0.0)  # beyond the last bump
    np.testing.assert_array_equal(shift[60:91], 0.0)  # between the first bump and the second
    single = faded_shifts(frames[:1], residuals[:1], 300, 60)
    step = np.linalg.norm(np.diff(single, axis=0), axis=-1).max()
    assert step == pytest.approx(np.pi / 2 * np.linalg.norm(residuals[0]) / 60, rel=1e-3)  # the stated peak
    assert faded_shifts(np.zeros(0, dtype=np.intp), np.zeros((0, 2)), 5, 3).shape == (5, 2)
    with pytest.raises(MotionError, match="residual per frame"):
        faded_shifts(frames, residuals[:2], 300, 60)
    with pytest.raises(MotionError, match="at least one frame"):
        faded_shifts(frames, residuals, 300, 0)
