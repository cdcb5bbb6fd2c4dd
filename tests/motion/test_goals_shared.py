"""Goals between characters (motion.goals: MeetGoal, ApartGoal, HoldGoal) measured on positions
built by hand, so every figure is known."""

from __future__ import annotations

import numpy as np
import pytest

from motion.goals import ApartGoal, Character, HoldGoal, MeetGoal, ObstacleGoal, Point, measure
from motion.regions import FloorRegion
from motion.skeleton import Skeleton


def two_points() -> tuple[np.ndarray, tuple[Character, ...]]:
    """Two one-joint characters (joint 0 is a static world root): a at x = t / 10, b at x = 2, so
    they are 2 - t / 10 m apart at frame t (10 frames); b's joint 1 m up."""
    sk = Skeleton(("hip",), np.array([-1]), np.zeros((1, 3)), (("Xposition", "Yposition", "Zposition"),))
    pos = np.zeros((10, 3, 3))
    pos[:, 1, 0] = np.arange(10) / 10
    pos[:, 2, 0] = 2.0
    pos[:, 2, 1] = 1.0
    chars = tuple(Character(np.array([j]), sk, f"c{j - 1}") for j in (1, 2))
    return pos, chars


def test_meet_between_joints_is_a_3d_distance() -> None:
    pos, chars = two_points()
    g = MeetGoal("shared[0]", 5, Point(0, 1, "c0.a"), Point(1, 2, "c1.b"), distance_m=0.5)
    e, why = measure(g, pos, 30.0, chars)
    d = float(np.hypot(1.5, 1.0))
    assert e["distance_cm"] == pytest.approx(100 * d, abs=1e-3)
    assert e["error_cm"] == pytest.approx(100 * (d - 0.5), abs=1e-3)
    assert not e["satisfied"] and why is not None and why.startswith("shared[0] (frame 5)")
    ok = MeetGoal("m", 5, Point(0, 1), Point(1, 2), distance_m=d, tolerance_cm=1.0)
    assert measure(ok, pos, 30.0, chars)[0]["satisfied"]
    late = MeetGoal("m", 10, Point(0, 1), Point(1, 2))
    assert measure(late, pos, 30.0, chars)[0]["missing"]


def test_apart_finds_the_closest_frame_and_counts_the_frames_under() -> None:
    pos, chars = two_points()
    g = ApartGoal("shared[1]", Point(0, 1, "c0.a"), Point(1, 2, "c1.b"), min_m=1.7, start=2, end=9)
    e, why = measure(g, pos, 30.0, chars)
    d = np.hypot(2.0 - np.arange(2, 9) / 10, 1.0)
    assert e["min_distance_cm"] == pytest.approx(100 * d.min(), abs=1e-3) and e["frame"] == 8
    assert e["frames"] == int((d < 1.7).sum()) == 2 and not e["satisfied"] and why is not None
    assert measure(ApartGoal("x", Point(0, 1), Point(1, 2), min_m=1.0), pos, 30.0, chars)[0]["satisfied"]


def test_hold_counts_the_frames_within_reach() -> None:
    pos, chars = two_points()
    g = HoldGoal(
        "hold[0]", Point(0, 1, "a"), Point(1, 2, "b"), max_m=1.6, min_fraction=0.5, extra={"examples": 1}
    )
    e, why = measure(g, pos, 30.0, chars)
    d = np.hypot(2.0 - np.arange(10) / 10, 1.0)
    assert e["held_fraction"] == pytest.approx(float(np.mean(d <= 1.6)), abs=1e-4)
    assert e["median_cm"] == pytest.approx(100 * float(np.median(d)), abs=1e-3)
    assert e["examples"] == 1 and e["satisfied"] == (float(np.mean(d <= 1.6)) >= 0.5)


def test_obstacle_of_one_character_ignores_the_others() -> None:
    pos, chars = two_points()
    region = FloorRegion.disc((2.0, 0.0), 0.5)
    assert not measure(ObstacleGoal("o", region), pos, 30.0, chars)[0]["satisfied"]
    assert measure(ObstacleGoal("o", region, characters=(0,)), pos, 30.0, chars)[0]["satisfied"]
