"""Contacts, cut smoothing, features and metrics on synthetic and real motion."""

from __future__ import annotations

import numpy as np
import pytest

from motion import read_bvh
from motion.contacts import detect_contacts, foot_joints
from motion.features import torso_features
from motion.metrics import cut_discontinuity, foot_slip, jerk, points_jerk
from motion.samples import sample_path
from motion.smoothing import displacement_profile, smooth_cuts

from .synthetic import walking_biped


def test_displacement_profile_is_the_papers() -> None:
    y = displacement_profile(100, 50, 30)
    assert y[19] == 0 and y[81] == 0
    assert y[49] == pytest.approx(0.5 * (29 / 30) ** 2)
    assert y[50] == pytest.approx(-0.5)
    assert y[80] == pytest.approx(0.0)
    # continuous except for the unit jump at the cut, with matching slopes (C1)
    assert y[49] - y[50] == pytest.approx(1.0, abs=0.05)
    assert (y[49] - y[48]) == pytest.approx(y[51] - y[50], abs=2e-3)
    lin = displacement_profile(100, 50, 30, "linear")
    assert lin[50] == pytest.approx(-0.5) and lin[65] == pytest.approx(-0.25)


def concat_with_jump() -> tuple:
    m = walking_biped(frames=200, fps=30.0)
    cut = 100
    root = m.root_positions.copy()
    root[cut:] += np.array([0.3, 0.0, -0.2])  # a 36 cm jump
    q = m.rotations.copy()
    q[cut:, 2] = q[cut:, 2][:, [1, 0, 2, 3]] * np.array([1, 1, 1, 1])  # a rotation jump at the knee
    q[cut:, 2] /= np.linalg.norm(q[cut:, 2], axis=-1, keepdims=True)
    from dataclasses import replace

    return replace(m, root_positions=root, rotations=q), cut, m


@pytest.mark.parametrize("kernel", ["arikan", "linear"])
def test_smooth_cuts_removes_discontinuity(kernel: str) -> None:
    jumpy, cut, clean = concat_with_jump()
    before = cut_discontinuity(jumpy, [cut])[0]
    after = cut_discontinuity(smooth_cuts(jumpy, [cut], 15, kernel), [cut])[0]
    assert before > 0.3
    assert after < 0.01 * before
    # frames far from the cut are untouched
    sm = smooth_cuts(jumpy, [cut], 15, kernel)
    np.testing.assert_allclose(sm.global_positions()[:80], jumpy.global_positions()[:80], atol=1e-12)


def test_smoothing_lowers_jerk_on_real_cut() -> None:
    m = read_bvh(sample_path("salsa-leader")).slice(0, 1000)
    from dataclasses import replace

    a, b = m.slice(0, 300), m.slice(600, 900)
    cat = replace(
        a,
        root_positions=np.concatenate([a.root_positions, b.root_positions]),
        rotations=np.concatenate([a.rotations, b.rotations]),
    )
    smoothed = smooth_cuts(cat, [300], 60)
    assert cut_discontinuity(smoothed, [300])[0] < 0.05 * cut_discontinuity(cat, [300])[0]
    assert jerk(smoothed) < jerk(cat)


def test_contacts_on_real_walk_alternate() -> None:
    m = read_bvh(sample_path("walk")).slice(1)  # frame 0 is a synthetic reference pose
    joints, contacts = detect_contacts(m)
    names = [m.skeleton.names[j] for j in joints]
    assert names == ["rFoot", "lFoot"] or sorted(names) == ["lFoot", "rFoot"]
    frac = contacts.mean(axis=0)
    assert np.all((frac > 0.15) & (frac < 0.8)), frac
    # ankle joints are planted from heel strike to heel-off (about 30-40% of a gait cycle each),
    # so at least one of them is down more than half the time
    assert contacts.any(axis=1).mean() > 0.5
    assert foot_slip(m, contacts=contacts, joints=joints) < 0.5


def test_foot_joints_by_name_and_torso_features() -> None:
    m = walking_biped(frames=90, noise=0.0)
    feet = foot_joints(m.skeleton)
    assert [m.skeleton.names[j] for j in feet] == ["lFoot", "rFoot"]
    tf = torso_features(m, ["lFoot", "rFoot", "head"])
    assert tf.positions.shape == (90, 3, 3)
    # walking straight ahead at 1.2 m/s: forward (+Z) velocity in the ground frame
    np.testing.assert_allclose(tf.root_velocity[5:-5, 2], 1.2, atol=0.05)
    np.testing.assert_allclose(tf.turn_rate, 0.0, atol=1e-6)
    rotated = torso_features(
        walking_biped(frames=90, heading_deg=120.0, noise=0.0), ["lFoot", "rFoot", "head"]
    )
    np.testing.assert_allclose(rotated.positions, tf.positions, atol=1e-6)
    assert tf.stacked().shape == (90, 3 * 6 + 7)


def test_points_jerk_of_a_cubic_is_its_third_derivative() -> None:
    fps = 50.0
    t = np.arange(40) / fps
    points = np.zeros((40, 2, 3))
    points[:, 0, 0] = 2.0 * t**3  # third derivative 12 m/s^3 on one point, 0 on the other
    assert points_jerk(points, fps) == pytest.approx(6.0)
    assert points_jerk(points[:3], fps) == 0.0
