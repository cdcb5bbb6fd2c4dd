"""Floor transforms of whole motions, with and without a static reference root joint."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion import read_bvh
from motion.goals import LoopGoal, PoseGoal, body_pose
from motion.ground import (
    apply_floor_transform,
    body_joints,
    pin_reference_root,
    pin_reference_roots,
    static_reference_root,
    usual_reference_root,
)
from motion.quality import QualityInputs, assess
from motion.samples import sample_path

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
BANDAI_WALK = DATA / "bandai-namco" / "dataset-2" / "dataset-2_walk_normal_001.bvh"
BANDAI_BACK = DATA / "bandai-namco" / "dataset-1" / "dataset-1_walk-back_normal_001.bvh"


def _expected(positions: np.ndarray, theta: np.ndarray, shift_u: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    x, z = positions[..., 0], positions[..., 2]
    out = positions.copy()
    out[..., 0] = c * x + s * z + shift_u[:, None, 0]
    out[..., 2] = -s * x + c * z + shift_u[:, None, 1]
    return out


def _transform(frames: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    return rng.uniform(-np.pi, np.pi, frames), rng.uniform(-3, 3, (frames, 2))


def test_moving_joint_zero_moves_every_joint_rigidly() -> None:
    walk = read_bvh(sample_path("walk"))
    assert static_reference_root([walk]) is None  # the hips move: no static reference
    theta, shift = _transform(walk.num_frames)
    moved = apply_floor_transform(walk, theta, shift)
    want = _expected(walk.global_positions(), theta, shift / walk.metres_per_unit)
    np.testing.assert_allclose(moved.global_positions(), want, atol=1e-9 * np.abs(want).max())


@pytest.mark.skipif(not BANDAI_WALK.exists(), reason=f"shared data not found ({BANDAI_WALK})")
def test_a_static_reference_root_stays_and_its_children_move() -> None:
    walk = read_bvh(BANDAI_WALK)
    static = static_reference_root([walk])
    assert static is not None
    theta, shift = _transform(walk.num_frames)
    moved = apply_floor_transform(walk, theta, shift, static)
    np.testing.assert_array_equal(moved.root_positions, walk.root_positions)
    np.testing.assert_array_equal(moved.rotations[:, 0], walk.rotations[:, 0])
    pos = walk.global_positions()
    want = _expected(pos[:, 1:], theta, shift / walk.metres_per_unit)
    np.testing.assert_allclose(moved.global_positions()[:, 1:], want, atol=1e-9 * np.abs(want).max())
    assert static_reference_root([walk, apply_floor_transform(walk, theta, shift)]) is None
    assert static_reference_root([]) is None


@pytest.mark.skipif(not BANDAI_BACK.exists(), reason=f"shared data not found ({BANDAI_BACK})")
def test_a_clip_whose_reference_root_moves_is_pinned_to_the_usual_pose() -> None:
    """``dataset-1_walk-back_normal_001`` translates ``joint_Root`` too: the strict rule finds no
    static root, the usual one does, and pinning keeps every other joint where it was."""
    walk, back = read_bvh(BANDAI_WALK), read_bvh(BANDAI_BACK)
    assert np.abs(back.root_positions).max() > 1.0  # joint_Root moves in this clip
    assert static_reference_root([walk, back]) is None
    static, moving = usual_reference_root([walk, back])
    assert static is not None and moving.tolist() == [False, True]
    np.testing.assert_array_equal(static[0], walk.root_positions[0])
    pinned = pin_reference_root(back, static)
    assert np.all(pinned.root_positions == static[0])
    pos = back.global_positions()
    np.testing.assert_allclose(pinned.global_positions()[:, 1:], pos[:, 1:], atol=1e-9 * np.abs(pos).max())
    assert static_reference_root([walk, pinned]) is not None
    # most frames must hold the pose, and the clips that hold it must agree
    assert usual_reference_root([back])[0] is None
    moved = apply_floor_transform(walk, np.full(walk.num_frames, 0.5), np.ones((walk.num_frames, 2)))
    assert usual_reference_root([walk, moved])[0] is None
    assert usual_reference_root([walk, walk])[1].tolist() == [False, False]


@pytest.mark.skipif(not BANDAI_BACK.exists(), reason=f"shared data not found ({BANDAI_BACK})")
def test_pin_reference_roots_pins_only_the_clips_that_move_it() -> None:
    walk, back = read_bvh(BANDAI_WALK), read_bvh(BANDAI_BACK)
    static, motions = pin_reference_roots([walk, back])
    assert static is not None and motions[0] is walk and motions[1] is not back
    np.testing.assert_array_equal(motions[1].root_positions, pin_reference_root(back, static).root_positions)
    static, motions = pin_reference_roots([walk, walk])
    assert static is not None and all(m is walk for m in motions)  # nothing to pin: the same objects
    assert pin_reference_roots([back]) == (None, (back,))


@pytest.mark.skipif(not BANDAI_WALK.exists(), reason=f"shared data not found ({BANDAI_WALK})")
def test_a_pose_goal_compares_the_body_not_a_static_reference_joint() -> None:
    """Placing a Bandai-Namco body elsewhere leaves ``joint_Root`` at the origin: the pose of the
    placed frame is the source frame's pose (the body's joints), whatever joint 0 does."""
    walk = read_bvh(BANDAI_WALK).to_units("m")
    static = static_reference_root([walk])
    n = walk.num_frames
    moved = apply_floor_transform(walk, np.full(n, 1.0), np.full((n, 2), 4.0), static)
    pose = body_pose(walk.global_positions()[40:41], walk.skeleton)[0]
    report = assess(moved, QualityInputs(goals=(PoseGoal("frame[0]", 40, pose),)))
    assert report.constraint_errors["frame[0]"]["pose_cm"] < 1e-6
    assert body_joints(walk.skeleton).tolist() == list(range(1, walk.num_joints))
    looped = assess(moved.slice(40, 41 + n // 2), QualityInputs(goals=(LoopGoal(),)))
    assert looped.constraint_errors["loop"]["pose_cm"] > 1.0  # a real pose change is still measured
