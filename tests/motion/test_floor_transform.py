"""Floor transforms of whole motions, with and without a static reference root joint."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion import read_bvh
from motion.ground import apply_floor_transform, static_reference_root
from motion.samples import sample_path

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
BANDAI_WALK = DATA / "bandai-namco" / "dataset-2" / "dataset-2_walk_normal_001.bvh"


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
