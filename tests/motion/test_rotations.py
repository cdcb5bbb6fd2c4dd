"""Quaternion helpers against scipy and against their own inverses."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from motion import MotionError
from motion import rotations as rot

RNG = np.random.default_rng(7)


def random_quats(n: int) -> np.ndarray:
    return Rotation.random(n, random_state=3).as_quat()


def same_rotation(a: np.ndarray, b: np.ndarray, tol: float = 1e-12) -> bool:
    return bool(np.all(np.minimum(np.abs(a - b).max(-1), np.abs(a + b).max(-1)) < tol))


def test_multiply_matches_scipy_composition() -> None:
    a, b = random_quats(50), random_quats(50)[::-1]
    expected = (Rotation.from_quat(a) * Rotation.from_quat(b)).as_quat()
    assert same_rotation(rot.multiply(a, b), expected)


def test_rotate_and_matrix_match_scipy() -> None:
    q = random_quats(20)
    v = RNG.normal(size=(20, 3))
    np.testing.assert_allclose(rot.rotate(q, v), Rotation.from_quat(q).apply(v), atol=1e-12)
    np.testing.assert_allclose(rot.to_matrix(q), Rotation.from_quat(q).as_matrix(), atol=1e-12)
    assert same_rotation(rot.from_matrix(rot.to_matrix(q)), q)


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX", "ZXZ", "X", "YZ"])
def test_euler_round_trip_and_scipy(order: str) -> None:
    angles = RNG.uniform(-170, 170, size=(200, len(order)))
    if len(order) == 3 and order[0] != order[2]:
        angles[:, 1] = RNG.uniform(-85, 85, size=200)
    q = rot.from_euler(order, angles)
    assert same_rotation(q, Rotation.from_euler(order, angles, degrees=True).as_quat(), 1e-12)
    if len(order) == 3 and order[0] == order[2]:
        return  # proper Euler angles use another canonical range
    np.testing.assert_allclose(rot.to_euler(order, q), angles, atol=1e-9)


def test_from_euler_handles_angles_beyond_180() -> None:
    angles = RNG.uniform(-900, 900, size=(100, 3))
    angles[:3] = [180.0, -180.0, 179.9999999]
    q = rot.from_euler("ZXY", angles)
    assert same_rotation(q, Rotation.from_euler("ZXY", angles, degrees=True).as_quat(), 1e-14)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-15)


def test_from_euler_rejects_bad_orders() -> None:
    with pytest.raises(MotionError):
        rot.from_euler("XQ", np.zeros((1, 2)))
    with pytest.raises(MotionError):
        rot.from_euler("XYZ", np.zeros((1, 2)))


def test_log_exp_inverse_and_angle() -> None:
    q = rot.standardize(random_quats(100))
    assert same_rotation(rot.exp(rot.log(q)), q)
    r = rot.log(q)
    np.testing.assert_allclose(np.linalg.norm(r, axis=-1), rot.angle_between(q, rot.IDENTITY), atol=1e-12)
    assert same_rotation(rot.exp(np.zeros((1, 3))), rot.identity((1,)))


def test_slerp_endpoints_midpoint_and_short_arc() -> None:
    a, b = random_quats(10), random_quats(10)[::-1]
    assert same_rotation(rot.slerp(a, b, 0.0), a)
    assert same_rotation(rot.slerp(a, b, 1.0), b)
    mid = rot.slerp(a, b, 0.5)
    np.testing.assert_allclose(rot.angle_between(a, mid), rot.angle_between(mid, b), atol=1e-12)
    # -b is the same rotation: slerp must take the same (short) path
    assert same_rotation(rot.slerp(a, -b, 0.5), mid)


def test_make_continuous_removes_sign_flips() -> None:
    q = random_quats(1)[0] * np.ones((6, 1))
    q[[1, 3, 4]] *= -1
    c = rot.make_continuous(q)
    assert np.all(np.sum(c[1:] * c[:-1], axis=-1) > 0)
    assert same_rotation(c, q)


def test_yaw_convention() -> None:
    # heading 90 deg = facing +X (DESIGN.md): rotating +Z about +Y by +90 deg gives +X
    q = rot.from_yaw(np.radians([0.0, 90.0, -45.0]))
    np.testing.assert_allclose(
        rot.rotate(q, np.array([0.0, 0, 1])), [[0, 0, 1], [1, 0, 0], [-(0.5**0.5), 0, 0.5**0.5]], atol=1e-12
    )
    np.testing.assert_allclose(rot.yaw(q), np.radians([0.0, 90.0, -45.0]), atol=1e-12)


def test_normalize_rejects_zero() -> None:
    with pytest.raises(MotionError):
        rot.normalize(np.zeros((2, 4)))


def test_wrap_angle_and_rotate_floor_agree_with_yaw() -> None:
    """The floor helpers every engine uses: angles wrap to [-pi, pi); a floor vector turned by the
    yaw of a rotation is where that rotation takes it (Y up)."""
    a = np.array([-3 * np.pi, -np.pi, 0.0, np.pi, 2.5 * np.pi, 7.0])
    w = rot.wrap_angle(a)
    assert (w >= -np.pi).all() and (w < np.pi).all()
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
    rng = np.random.default_rng(0)
    theta, xz = rng.uniform(-4, 4, 20), rng.normal(size=(20, 2))
    v3 = np.stack((xz[:, 0], np.zeros(20), xz[:, 1]), axis=1)
    turned = Rotation.from_quat(rot.from_yaw(theta)).apply(v3)
    np.testing.assert_allclose(rot.rotate_floor(theta, xz), turned[:, [0, 2]], atol=1e-12)
