"""Foot-skate cleanup (motion.footskate): synthetic sliding feet get pinned, real walks slip less."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion import Motion, MotionError, Skeleton
from motion import rotations as rot
from motion.contacts import detect_contacts
from motion.footskate import _lift_toe, leg_chains, pin_corrections, remove_foot_skate, solve_foot_skate
from motion.io import load_motion
from motion.metrics import foot_slip
from motion.skeleton import default_channels

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"

# hips -> (thigh, shin, foot, toe) x 2 + spine; metres, Y up, facing +Z
NAMES = ("hips", "lThigh", "lShin", "lFoot", "lToe", "rThigh", "rShin", "rFoot", "rToe", "spine")
PARENTS = np.array([-1, 0, 1, 2, 3, 0, 5, 6, 7, 0])
OFFSETS = np.array(
    [
        [0.0, 0.9, 0.0],
        [0.1, -0.05, 0.0], [0.0, -0.42, 0.0], [0.0, -0.4, 0.0], [0.0, -0.05, 0.14],
        [-0.1, -0.05, 0.0], [0.0, -0.42, 0.0], [0.0, -0.4, 0.0], [0.0, -0.05, 0.14],
        [0.0, 0.3, 0.0],
    ]
)  # fmt: skip
FPS = 30.0


def sliding_biped(frames: int = 60, speed: float = 0.4) -> Motion:
    """Knees bent, hips 0.82 m high, gliding forward at ``speed`` m/s: planted feet slide."""
    sk = Skeleton(NAMES, PARENTS, OFFSETS, default_channels(len(NAMES)))
    t = np.arange(frames) / FPS
    root = np.zeros((frames, 3))
    root[:, 1] = 0.82
    root[:, 2] = speed * t
    q = rot.identity((frames, len(NAMES)))
    x = np.array([1.0, 0.0, 0.0])
    for hip, knee, ankle, phase in ((1, 2, 3, 0.0), (5, 6, 7, 1.0)):
        wobble = 0.05 * np.sin(2 * np.pi * t + phase)
        q[:, hip] = rot.from_axis_angle(x, -0.35 + wobble)
        q[:, knee] = rot.from_axis_angle(x, 0.7 - wobble)
        q[:, ankle] = rot.from_axis_angle(x, -0.35)
    q[:, 0] = rot.from_yaw(np.full(frames, 0.1))
    return Motion(sk, root, q, FPS, units="m", name="sliding")


def bone_lengths(m: Motion) -> np.ndarray:
    pos = m.global_positions()
    return np.asarray(np.linalg.norm(pos[:, 1:] - pos[:, PARENTS[1:]], axis=-1))


def test_sliding_ankle_is_pinned_and_lengths_kept() -> None:
    m = sliding_biped()
    joints = np.array([3])
    flags = np.zeros((m.num_frames, 1), dtype=bool)
    flags[20:40, 0] = True
    before = foot_slip(m, contacts=flags, joints=joints)
    res = solve_foot_skate(m, (joints, flags), blend_s=0.1)
    out = res.motion
    after = foot_slip(out, contacts=flags, joints=joints)
    assert before > 0.25
    assert after < 1e-6
    assert res.residual.max() < 1e-9
    pos = out.global_positions()
    planted = pos[20:40, 3]
    assert np.ptp(planted, axis=0).max() < 1e-9  # one target, height included
    assert np.allclose(bone_lengths(out), bone_lengths(m), atol=1e-12)
    np.testing.assert_array_equal(out.root_positions, m.root_positions)
    # blend window is 3 frames: frames outside [17, 43) are bit-for-bit the input
    untouched = np.r_[0:17, 43:60]
    np.testing.assert_array_equal(out.rotations[untouched], m.rotations[untouched])
    changed = np.flatnonzero(np.abs(out.rotations - m.rotations).max(axis=(1, 2)) > 0)
    assert changed.min() >= 17 and changed.max() <= 42
    # only the left leg's hip, knee and ankle rotations move
    moved = np.flatnonzero(np.abs(out.rotations - m.rotations).max(axis=(0, 2)) > 0)
    assert set(moved) == {1, 2, 3}
    # the knee keeps bending forward (its original side of the hip-ankle line)
    assert np.all(pos[20:40, 2, 2] > pos[20:40, 1, 2] - 0.05)


def test_fade_is_smooth_and_short_gaps_are_bridged() -> None:
    positions = np.zeros((40, 3))
    positions[:, 0] = np.arange(40) * 0.01
    flags = np.zeros(40, dtype=bool)
    flags[5:15] = True
    flags[18:30] = True  # gap of 3 frames < 2 x blend: interpolated
    corr, weight = pin_corrections(positions, flags, blend=4)
    assert np.all(weight[5:30] == 1.0)
    assert weight[0] == 0.0 and weight[35] == 0.0 and weight[34] == 0.0
    assert 0.0 < weight[31] < 1.0 and weight[30] > weight[31] > weight[32] > weight[33]
    targets = positions + corr
    np.testing.assert_allclose(targets[5:15, 0], positions[5:15, 0].mean())
    np.testing.assert_allclose(targets[18:30, 0], positions[18:30, 0].mean())
    # across the short gap the target slides monotonically from one run's target to the next
    assert np.all(np.diff(targets[14:19, 0]) > 0)
    # after the last run the correction fades monotonically to exactly zero
    fade = np.abs(corr[29:36, 0])
    assert np.all(np.diff(fade) <= 0) and fade[-1] == 0.0 and fade[1] > 0.0
    np.testing.assert_array_equal(corr[:1], 0.0)


def test_toe_contacts_move_or_turn_the_foot() -> None:
    m = sliding_biped(speed=0.3)
    joints = np.array([3, 4, 7, 8])
    flags = np.zeros((m.num_frames, 4), dtype=bool)
    flags[10:30, 0] = True  # left foot flat: heel and toe planted
    flags[10:30, 1] = True
    flags[25:50, 3] = True  # right toe only (heel off): the whole foot follows the toe
    legs = leg_chains(m, joints)
    assert [(leg.hip, leg.knee, leg.ankle, leg.toe) for leg in legs] == [(1, 2, 3, 4), (5, 6, 7, 8)]
    res = solve_foot_skate(m, (joints, flags), blend_s=0.1)
    pos = res.motion.global_positions()
    assert res.residual.max() < 1e-3
    for j, run in ((3, slice(10, 30)), (4, slice(10, 30)), (8, slice(25, 50))):
        assert np.ptp(pos[run, j], axis=0).max() < 2e-3, j
    assert np.allclose(bone_lengths(res.motion), bone_lengths(m), atol=1e-12)


def straightening_biped(frames: int = 60, bent_frames: int = 20) -> Motion:
    """Standing on straight legs (the ankles on the floor, y = 0) after ``bent_frames`` frames of
    knees bent 35 degrees: the left knee then wavers through straight (+-0.9 degrees, forward and
    backward), as a nearly straight mocap knee does."""
    sk = Skeleton(NAMES, PARENTS, OFFSETS, default_channels(len(NAMES)))
    t = np.arange(frames) / FPS
    root = np.zeros((frames, 3))
    root[:, 1] = 0.87
    q = rot.identity((frames, len(NAMES)))
    x = np.array([1.0, 0.0, 0.0])
    knee = 0.015 * np.sin(2 * np.pi * 3.0 * t)
    knee[:bent_frames] = 0.6
    q[:, 2] = rot.from_axis_angle(x, knee)
    q[:, 1] = rot.from_axis_angle(x, np.where(knee > 0.3, -0.3, 0.0))
    q[:, 6] = rot.from_axis_angle(x, knee[::-1])
    return Motion(sk, root, q, FPS, units="m", name="straightening")


@pytest.mark.parametrize("bent_frames", [20, 0], ids=["hinge from the bent frames", "no bent frames"])
def test_straight_knee_bends_forward_every_frame(bent_frames: int) -> None:
    # a floor above the ankles makes the IK bend the straight knee: it must bend forward (the shin
    # swinging back) in every frame, however the knee's own plane turns as it passes straight
    # (bending it backwards in the frames where it was hyperextended by 0.01 radian was a 200 m/s^2
    # spike in graph outputs at a cut)
    m = straightening_biped(bent_frames=bent_frames)
    joints = np.array([3])
    flags = np.zeros((m.num_frames, 1), dtype=bool)
    res = solve_foot_skate(m, (joints, flags), floor=np.array([0.05]))
    pos = res.motion.global_positions()
    lifted = slice(bent_frames, None)
    assert np.all(pos[lifted, 3, 1] > 0.045)  # the ankle lifted to the floor
    hip, knee, ankle = pos[lifted, 1], pos[lifted, 2], pos[lifted, 3]
    ahead = knee[:, 2] - 0.5 * (hip[:, 2] + ankle[:, 2])
    assert np.all(ahead > 0.05)  # metres in front of the hip-ankle line (facing +Z)
    accel = np.linalg.norm(np.diff(knee, 2, axis=0), axis=-1) * FPS**2
    assert accel.max() < 5.0  # m/s^2: the knee moves smoothly
    assert np.allclose(bone_lengths(res.motion), bone_lengths(m), atol=1e-12)


def test_toe_never_sinks_below_its_floor_while_its_pin_fades_in() -> None:
    # heel and toe plant at frame 30, the heel 6 cm lower than it stands (a smoothed cut between
    # clips of different hip heights): in the fade-in frames the ankle's pin lowers the foot while
    # the toe turns only part of the way to its own target, which carried the toe through the
    # floor its target stays above (2.8 cm in a graph output; 0.7 cm here)
    m = sliding_biped(speed=0.0)
    pos = m.global_positions()
    joints = np.array([3, 4])
    flags = np.zeros((m.num_frames, 2), dtype=bool)
    flags[30:50] = True
    heights = pos[:, joints, 1].copy()
    heights[:, 0] -= 0.06
    toe_floor = float(pos[:, 4, 1].min())
    free = solve_foot_skate(m, (joints, flags), heights=heights, floor=np.array([-1.0, -1.0]))
    sunk = free.motion.global_positions()[:, 4, 1] < toe_floor - 1e-9
    assert np.flatnonzero(sunk).tolist() == [28, 29, 51]  # the case: without a floor the toe sinks
    res = solve_foot_skate(m, (joints, flags), heights=heights, floor=np.array([-1.0, toe_floor]))
    out, was = res.motion.global_positions(), free.motion.global_positions()
    assert out[:, 4, 1].min() >= toe_floor - 1e-9
    np.testing.assert_allclose(out[sunk, 4, 1], toe_floor, atol=1e-3)  # lifted to the floor
    # only the sinking frames change, and only that leg: the whole foot rises by what the toe
    # lacked (same orientation, same floor position), it does not tilt
    changed = np.abs(res.motion.rotations - free.motion.rotations).max(axis=2) > 0
    assert np.array_equal(changed.any(axis=1), sunk)
    assert set(np.flatnonzero(changed.any(axis=0))) <= {1, 2, 3}
    np.testing.assert_allclose(out[:, 4] - out[:, 3], was[:, 4] - was[:, 3], atol=1e-3)
    np.testing.assert_allclose(out[:, 3, [0, 2]], was[:, 3, [0, 2]], atol=1e-4)
    rise = out[sunk, 3, 1] - was[sunk, 3, 1]
    np.testing.assert_allclose(rise, toe_floor - was[sunk, 4, 1], atol=1e-3)
    assert rise.max() > 0.005
    assert np.allclose(bone_lengths(res.motion), bone_lengths(m), atol=1e-12)


def test_lift_toe_tilts_the_foot_up_to_the_floor() -> None:
    # the last resort of the toe floor (a leg that cannot lift its ankle as far as the toe needs):
    # the foot turns about the ankle, keeping its length and heading, until the toe is on the floor
    ankle = np.array([[0.0, 0.10, 0.0], [0.0, 0.10, 0.0], [0.0, 0.10, 0.0], [0.0, 0.10, 0.0]])
    foot = np.array([[0.0, -0.08, 0.10], [0.06, -0.12, 0.0], [0.0, -0.13, 0.0], [0.0, -0.02, 0.12]])
    q = _lift_toe(ankle, foot, 0.05)
    out = rot.rotate(q, foot)
    np.testing.assert_allclose(ankle[:3, 1] + out[:3, 1], 0.05, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), np.linalg.norm(foot, axis=1), atol=1e-12)
    np.testing.assert_allclose(out[0, [0, 2]] / np.linalg.norm(out[0, [0, 2]]), [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(out[1, [0, 2]] / np.linalg.norm(out[1, [0, 2]]), [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(q[3], rot.IDENTITY)  # above the floor: untouched
    assert np.isfinite(q).all()  # a foot pointing straight down (row 2) turns too


def test_out_of_reach_targets_report_residual_and_root_adjust_helps() -> None:
    m = sliding_biped(speed=1.5)  # 30 frames at 1.5 m/s: the foot cannot stay put
    joints = np.array([3])
    flags = np.zeros((m.num_frames, 1), dtype=bool)
    flags[10:50, 0] = True
    plain = solve_foot_skate(m, (joints, flags))
    assert plain.residual.max() > 0.05
    assert np.all(plain.root_shift == 0)
    adjusted = solve_foot_skate(m, (joints, flags), root_adjust=True, max_root_shift_m=0.05)
    shift = np.linalg.norm(adjusted.root_shift, axis=-1)
    assert 0 < shift.max() <= 0.05 + 1e-12
    assert adjusted.residual.max() < plain.residual.max()
    assert np.allclose(bone_lengths(adjusted.motion), bone_lengths(m), atol=1e-12)


def test_errors() -> None:
    m = sliding_biped(frames=10)
    with pytest.raises(MotionError, match="flags"):
        remove_foot_skate(m, (np.array([3]), np.zeros((9, 1), dtype=bool)))
    with pytest.raises(MotionError, match="blend_s"):
        remove_foot_skate(m, blend_s=-1.0)
    # a foot hanging straight off the root has no hip-knee-ankle chain
    offsets = np.array([[0.0, 1.0, 0.0], [0.0, -0.5, 0.0], [0.0, -0.4, 0.0]])
    sk = Skeleton(("root", "shin", "foot"), np.array([-1, 0, 1]), offsets, default_channels(3))
    tiny = Motion(sk, np.zeros((5, 3)), rot.identity((5, 3)), FPS, units="m")
    with pytest.raises(MotionError, match="no leg chain"):
        remove_foot_skate(tiny, (np.array([2]), np.ones((5, 1), dtype=bool)))
    # no contact: the input comes back unchanged
    same = remove_foot_skate(m, (np.array([3]), np.zeros((10, 1), dtype=bool)))
    np.testing.assert_array_equal(same.rotations, m.rotations)


REAL = [
    ("bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh", 0),
    ("cmu-walks/007_02.bvh", 1),  # frame 0 is a stray T-pose
    ("cmu-daz/walks/07_09.bvh", 1),
]


@pytest.mark.parametrize(("rel", "first"), REAL, ids=[r for r, _ in REAL])
def test_real_walk_slips_less(rel: str, first: int) -> None:
    path = DATA / rel
    if not path.is_file():
        pytest.skip(f"shared data not found: {path}")
    m = load_motion(path).slice(first, first + 240)
    contacts = detect_contacts(m)
    out = remove_foot_skate(m, contacts)
    p0, p1 = m.global_positions(), out.global_positions()
    before = foot_slip(m, p0, contacts[1], contacts[0])
    after = foot_slip(out, p1, contacts[1], contacts[0])
    disp = float(np.abs(p1 - p0).max() * m.metres_per_unit)
    print(f"{rel}: slip {before:.4f} -> {after:.4f} m/s, max joint displacement {disp:.3f} m")
    assert after < 0.5 * before
    assert after < 0.04  # what remains is where a planted foot is out of the leg's reach
    adjusted = solve_foot_skate(m, contacts, root_adjust=True)
    assert foot_slip(adjusted.motion, None, contacts[1], contacts[0]) < min(after, 0.02) + 1e-9
    assert np.linalg.norm(adjusted.root_shift, axis=-1).max() * m.metres_per_unit <= 0.05 + 1e-9
    assert disp < 0.15  # metres: a cleanup, not a new motion
    np.testing.assert_array_equal(out.root_positions, m.root_positions)
    lengths = np.linalg.norm(p1[:, 1:] - p1[:, m.skeleton.parents[1:]], axis=-1)
    ref = np.linalg.norm(p0[:, 1:] - p0[:, m.skeleton.parents[1:]], axis=-1)
    np.testing.assert_allclose(lengths, ref, atol=1e-9 * max(float(ref.max()), 1.0))
