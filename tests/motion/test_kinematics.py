"""Forward kinematics against a plain per-joint matrix implementation."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from motion import Motion, Skeleton
from motion.kinematics import forward_kinematics
from motion.skeleton import default_channels

from .synthetic import walking_biped


def reference_fk(
    parents: np.ndarray, translations: np.ndarray, quats: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Textbook FK: one joint at a time with scipy rotation matrices."""
    f, j = quats.shape[:2]
    mats = Rotation.from_quat(quats.reshape(-1, 4)).as_matrix().reshape(f, j, 3, 3)
    gm = np.zeros_like(mats)
    pos = np.zeros((f, j, 3))
    for k in range(j):
        p = parents[k]
        if p < 0:
            gm[:, k], pos[:, k] = mats[:, k], translations[:, k]
        else:
            gm[:, k] = gm[:, p] @ mats[:, k]
            pos[:, k] = pos[:, p] + np.einsum("fab,fb->fa", gm[:, p], translations[:, k])
    return pos, gm


def test_fk_matches_reference_on_walking_biped() -> None:
    m = walking_biped(frames=700)  # more frames than one FK block
    pos, grot = m.fk()
    ref_pos, ref_mats = reference_fk(m.skeleton.parents, m.local_translations(), m.rotations)
    np.testing.assert_allclose(pos, ref_pos, atol=1e-12)
    np.testing.assert_allclose(
        Rotation.from_quat(grot.reshape(-1, 4)).as_matrix().reshape(ref_mats.shape), ref_mats, atol=1e-12
    )


def test_fk_with_per_frame_translations_and_global_positions() -> None:
    m = walking_biped(frames=40)
    rng = np.random.default_rng(0)
    t = m.local_translations() + rng.normal(scale=0.01, size=(40, m.num_joints, 3))
    pos, _ = forward_kinematics(m.skeleton.parents, t, m.rotations)
    ref, _ = reference_fk(m.skeleton.parents, t, m.rotations)
    np.testing.assert_allclose(pos, ref, atol=1e-12)
    np.testing.assert_allclose(m.global_positions(), m.fk()[0], atol=0)


def test_golden_chain_by_hand() -> None:
    """Root at (1, 2, 3) rotated +90 deg about Y; child offset (0, 0, 1) rotated +90 deg about X;
    grandchild offset (0, 1, 0). By hand: R_y(90) maps +Z -> +X, so the child is at (2, 2, 3); the
    child's global rotation R_y(90) R_x(90) maps +Y -> R_y(90)(+Z) = +X, so the grandchild is at (3, 2, 3)."""
    sk = Skeleton(
        ("a", "b", "c"),
        np.array([-1, 0, 1]),
        np.array([[0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]]),
        default_channels(3),
    )
    q = np.zeros((1, 3, 4))
    q[0, 0] = [0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)]
    q[0, 1] = [np.sin(np.pi / 4), 0, 0, np.cos(np.pi / 4)]
    q[0, 2] = [0, 0, 0, 1]
    m = Motion(sk, np.array([[1.0, 2.0, 3.0]]), q, 30.0, units="m")
    np.testing.assert_allclose(m.global_positions()[0], [[1, 2, 3], [2, 2, 3], [3, 2, 3]], atol=1e-12)
