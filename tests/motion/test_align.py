"""Closed-form alignments against known transforms and brute force."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from motion import MotionError
from motion.align import apply_rigid_2d, kabsch, rigid_align_2d, rotation_from_covariance

RNG = np.random.default_rng(11)


def cost(src: np.ndarray, dst: np.ndarray, w: np.ndarray, theta: float, t: np.ndarray) -> float:
    moved = apply_rigid_2d(src, theta, t)
    return float((w * ((moved - dst)[..., [0, 2]] ** 2).sum(-1)).sum())


def test_recovers_exact_transform_batched() -> None:
    src = RNG.normal(size=(8, 20, 3))
    theta = RNG.uniform(-np.pi, np.pi, size=8)
    t = RNG.normal(size=(8, 2))
    th, tr = rigid_align_2d(src, apply_rigid_2d(src, theta, t))
    np.testing.assert_allclose(np.angle(np.exp(1j * (th - theta))), 0, atol=1e-12)
    np.testing.assert_allclose(tr, t, atol=1e-12)


def test_weighted_optimum_beats_brute_force_grid() -> None:
    src = RNG.normal(size=(15, 3))
    dst = apply_rigid_2d(src, 0.8, np.array([0.5, -1.0])) + RNG.normal(scale=0.3, size=(15, 3))
    w = RNG.uniform(0, 2, size=15)
    th, tr = rigid_align_2d(src, dst, w)
    best = cost(src, dst, w, float(th), tr)
    for cand in np.linspace(-np.pi, np.pi, 721):
        # for a fixed angle the best translation is the weighted mean difference
        moved = apply_rigid_2d(src, cand, np.zeros(2))
        t = ((w[:, None] * (dst - moved)[:, [0, 2]]).sum(0)) / w.sum()
        assert best <= cost(src, dst, w, cand, t) + 1e-9


def test_heights_do_not_matter_and_bad_input_raises() -> None:
    src = RNG.normal(size=(10, 3))
    dst = apply_rigid_2d(src, 1.0, np.array([1.0, 2.0]))
    dst[:, 1] += 5.0
    th, _ = rigid_align_2d(src, dst)
    assert abs(float(th) - 1.0) < 1e-12
    with pytest.raises(MotionError):
        rigid_align_2d(src, dst[:5])
    with pytest.raises(MotionError):
        rigid_align_2d(src, dst, np.zeros(10))


def test_kabsch_recovers_rotation_without_reflection() -> None:
    src = RNG.normal(size=(4, 12, 3))
    r = Rotation.random(4, random_state=2).as_matrix()
    t = RNG.normal(size=(4, 3))
    dst = np.einsum("bij,bnj->bni", r, src) + t[:, None]
    rr, tt = kabsch(src, dst)
    np.testing.assert_allclose(rr, r, atol=1e-10)
    np.testing.assert_allclose(tt, t, atol=1e-10)
    mirrored = src * np.array([-1.0, 1, 1])
    rr, _ = kabsch(src[0], mirrored[0])
    assert np.linalg.det(rr) == pytest.approx(1.0)


def test_rotation_from_covariance_gives_the_residual_in_closed_form() -> None:
    rng = np.random.default_rng(3)
    src = rng.normal(size=(5, 12, 3))
    tgt = rng.normal(size=(5, 12, 3))  # unrelated points: a real residual to predict
    cs, ct = src - src.mean(1, keepdims=True), tgt - tgt.mean(1, keepdims=True)
    h = np.einsum("mni,mnj->mij", cs, ct)
    rot, best = rotation_from_covariance(h)
    rot_k, trans = kabsch(src, tgt)
    np.testing.assert_allclose(rot, rot_k, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rot), 1.0)
    residual = ((np.einsum("mij,mnj->mni", rot, src) + trans[:, None] - tgt) ** 2).sum((1, 2))
    np.testing.assert_allclose(residual, (cs**2).sum((1, 2)) + (ct**2).sum((1, 2)) - 2 * best, rtol=1e-10)
    with pytest.raises(MotionError):
        rotation_from_covariance(np.zeros((4, 2, 2)))
