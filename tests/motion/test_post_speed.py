"""The fast paths of a control request's post-processing against the straightforward versions they
replace: vector lengths, cut smoothing in batches, sampling several clips, compiled forward
kinematics, cached skeleton and name lookups, and precomputed poses passed to the clean-ups."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from motion import Motion, MotionError, Skeleton
from motion import rotations as rot
from motion.bvh import bvh_text, parse_bvh
from motion.compiled import fast_fk, sample_into
from motion.footskate import remove_foot_skate
from motion.ground import facing_pairs
from motion.mirror import mirror_map
from motion.quality import assess
from motion.reach import reach
from motion.resample import sample_arrays_at, sample_at
from motion.smoothing import Kernel, displacement_profile, independent_batches, smooth_cuts
from motion.vectors import norms

from .synthetic import walking_biped


@pytest.mark.parametrize("n", [1, 2, 3, 4, 7])
def test_norms_are_numpys_bit_for_bit(n: int) -> None:
    rng = np.random.default_rng(n)
    x = rng.normal(size=(300, 5, n)) * rng.uniform(1e-3, 1e3, size=(300, 5, 1))
    strided = np.transpose(rng.normal(size=(n, 5, 300)), (2, 1, 0))  # not C-contiguous
    for v in (x, strided, np.diff(x, axis=0)):
        assert np.array_equal(norms(v), np.linalg.norm(v, axis=-1))


def test_quaternion_helpers_keep_their_values() -> None:
    rng = np.random.default_rng(3)
    q = rng.normal(size=(400, 6, 4))
    assert np.array_equal(rot.normalize(q), q / np.linalg.norm(q, axis=-1, keepdims=True))
    flipped = rot.make_continuous(rot.normalize(q))
    assert np.all(np.sum(flipped[1:] * flipped[:-1], axis=-1) >= 0)
    assert np.allclose(np.abs(flipped), np.abs(rot.normalize(q)))
    with pytest.raises(MotionError):
        rot.normalize(np.zeros((2, 4)))


def _smooth_one_by_one(
    motion: Motion, cuts: list[int], window: int, kernel: Kernel = "arikan"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cut smoothing as it was written before batching: one cut after the other."""

    def jump(x: np.ndarray, d: int) -> np.ndarray:
        step = x[d] - x[d - 1]
        nb = ([x[d - 1] - x[d - 2]] if d >= 2 else []) + ([x[d + 1] - x[d]] if d + 1 < x.shape[0] else [])
        return np.asarray(step - (np.mean(nb, axis=0) if nb else np.zeros_like(step)))

    def relative(q: np.ndarray, d: int) -> np.ndarray:
        steps = []
        if d >= 2:
            steps.append(rot.log(rot.multiply(rot.conjugate(q[d - 2]), q[d - 1])))
        if d + 1 < q.shape[0]:
            steps.append(rot.log(rot.multiply(rot.conjugate(q[d]), q[d + 1])))
        return rot.exp(np.mean(steps, axis=0)) if steps else rot.identity(q.shape[1:-1])

    n = motion.num_frames
    root, jt = motion.root_positions.copy(), motion.joint_translations.copy()
    q = rot.make_continuous(motion.rotations, axis=0)
    for d in sorted(set(cuts)):
        y = displacement_profile(n, d, window, kernel)
        active = np.flatnonzero(y)
        root[active] += y[active, None] * jump(root, d)
        if jt.shape[1]:
            jt[active] += y[active, None, None] * jump(jt, d)
        pred = rot.multiply(q[d - 1], relative(q, d))
        delta = rot.log(rot.multiply(q[d], rot.conjugate(pred)))
        q[active] = rot.multiply(rot.exp(y[active, None, None] * delta[None]), q[active])
    return root, rot.normalize(q), jt


def _jumpy(frames: int = 240) -> Motion:
    m = walking_biped(frames=frames, fps=30.0)
    rng = np.random.default_rng(5)
    q = m.rotations.copy()
    root = m.root_positions.copy()
    for c in (1, 30, 34, 90, 150, 200, 239):  # far apart, close together, and at both ends
        root[c:] += rng.normal(scale=0.1, size=3)
        q[c:] = rot.multiply(rot.exp(rng.normal(scale=0.2, size=(q.shape[1], 3))), q[c:])
    return replace(m, root_positions=root, rotations=q)


@pytest.mark.parametrize("kernel", ["arikan", "linear"])
@pytest.mark.parametrize("window", [1, 3, 12, 40])
def test_smooth_cuts_in_batches_is_one_cut_after_the_other(kernel: Kernel, window: int) -> None:
    m = _jumpy()
    cuts = [1, 30, 34, 90, 150, 200, 239]
    out = smooth_cuts(m, cuts, window, kernel)
    root, q, jt = _smooth_one_by_one(m, cuts, window, kernel)
    np.testing.assert_allclose(out.root_positions, root, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out.rotations, q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out.joint_translations, jt, rtol=0, atol=1e-12)


def test_independent_batches_split_where_cuts_touch() -> None:
    assert independent_batches([], 5) == []
    # window 5: a cut displaces c-4..c+4, a jump is measured on d-2..d+1 and displaces d-4..d+4
    assert independent_batches([10, 19, 27, 60], 5) == [[10, 19], [27, 60]]
    assert independent_batches([10, 18], 5) == [[10], [18]]
    assert independent_batches([10, 13], 1) == [[10, 13]]
    assert independent_batches([10, 12], 1) == [[10], [12]]


def test_smooth_cuts_checks_window_and_kernel_only_with_cuts() -> None:
    m = walking_biped(frames=50)
    assert np.array_equal(smooth_cuts(m, [], 0).root_positions, m.root_positions)
    with pytest.raises(MotionError):
        smooth_cuts(m, [10], 0)
    with pytest.raises(MotionError):
        smooth_cuts(m, [10], 5, "cubic")  # type: ignore[arg-type]
    with pytest.raises(MotionError):
        smooth_cuts(m, [50], 5)


def test_sample_arrays_at_is_sample_at() -> None:
    m = walking_biped(frames=80)
    frames = np.array([0.0, 0.25, 3.5, 41.0, 78.9, 79.0])
    root, q, jt = sample_arrays_at(m, frames)
    s = sample_at(m, frames)
    assert np.array_equal(root, s.root_positions) and np.array_equal(q, s.rotations)
    assert np.array_equal(jt, s.joint_translations)
    with pytest.raises(MotionError):
        sample_arrays_at(m, np.array([80.0]))


def _translated_biped() -> Motion:
    """A walking biped whose knee has animated position channels."""
    m = walking_biped(frames=300)
    sk = m.skeleton
    chans = list(sk.channels)
    chans[2] = ("Xposition", "Yposition", "Zposition", *chans[2][-3:])
    sk2 = Skeleton(sk.names, sk.parents, sk.offsets, tuple(chans), sk.end_site_parents, sk.end_site_offsets)
    rng = np.random.default_rng(2)
    jt = sk.offsets[2] + rng.normal(scale=0.01, size=(m.num_frames, 1, 3))
    return replace(m, skeleton=sk2, joint_translations=jt)


def test_fast_fk_is_fk() -> None:
    for m in (walking_biped(frames=1500), _translated_biped()):
        pos, grot = fast_fk(m)
        ref_pos, ref_rot = m.fk()
        np.testing.assert_allclose(pos, ref_pos, rtol=0, atol=1e-12)
        assert np.array_equal(grot, ref_rot)


def test_translated_joints_are_found_once_and_read_only() -> None:
    m = _translated_biped()
    tj = m.skeleton.translated_joints
    assert tj.tolist() == [2] and tj is m.skeleton.translated_joints
    with pytest.raises(ValueError, match="read-only"):
        tj[0] = 1
    assert walking_biped(frames=5).skeleton.translated_joints.size == 0


def test_cached_name_lookups_return_fresh_arrays() -> None:
    names = ("hip", "lThigh", "rThigh", "lShin", "rShin")
    partner, side = mirror_map(names)
    partner[:] = 0
    side[:] = 0
    again, side2 = mirror_map(list(names))
    assert again.tolist() == [0, 2, 1, 4, 3] and side2.tolist() == [0, 1, -1, 1, -1]
    sk = walking_biped(frames=5).skeleton
    pairs = facing_pairs(sk)
    pairs.append((0, 0))
    assert facing_pairs(sk) == pairs[:-1]


def test_cleanups_take_the_pose_they_would_compute() -> None:
    m = walking_biped(frames=200)
    fk = fast_fk(m)
    feet = np.array([m.skeleton.index(n) for n in m.skeleton.names if "foot" in n.lower()], dtype=np.intp)
    flags = np.zeros((m.num_frames, feet.size), dtype=bool)
    flags[20:60, 0] = flags[80:130, -1] = True
    a = remove_foot_skate(m, (feet, flags))
    b = remove_foot_skate(m, (feet, flags), fk=fk)
    np.testing.assert_allclose(a.rotations, b.rotations, rtol=0, atol=1e-12)
    hand = feet[:1]
    targets = fk[0][:, hand] + 0.05
    w = np.full((m.num_frames, 1), 0.5)
    np.testing.assert_allclose(
        reach(m, hand, targets, w).rotations, reach(m, hand, targets, w, fk).rotations, rtol=0, atol=1e-12
    )
    r1, r2 = assess(m), assess(m, positions=fk[0])
    assert r1.metrics == pytest.approx(r2.metrics, rel=1e-9)


def test_sample_into_writes_sample_at_into_rows() -> None:
    m = _translated_biped()
    frames = np.array([0.0, 0.25, 3.5, 41.0, 298.9, 299.0, 150.5])
    rows = np.array([6, 0, 2, 1, 3, 5, 4])
    root = np.full((7, 3), np.nan)
    q = np.full((7, m.num_joints, 4), np.nan)
    jt = np.full((7, 1, 3), np.nan)
    sample_into(m, frames, rows, root, q, jt)
    ref = sample_at(m, frames)
    np.testing.assert_allclose(root[rows], ref.root_positions, rtol=0, atol=1e-15)
    np.testing.assert_allclose(jt[rows], ref.joint_translations, rtol=0, atol=1e-15)
    np.testing.assert_allclose(q[rows], ref.rotations, rtol=0, atol=1e-15)
    # opposite hemispheres take the shorter arc, and equal rotations stay put
    flipped = replace(
        m, rotations=np.where(np.arange(m.num_frames)[:, None, None] % 2 == 1, -m.rotations, m.rotations)
    )
    sample_into(flipped, frames, rows, root, q, jt)
    np.testing.assert_allclose(q[rows], sample_at(flipped, frames).rotations, rtol=0, atol=1e-15)
    with pytest.raises(MotionError):
        sample_into(m, np.array([299.5]), np.array([0]), root, q, jt)
    with pytest.raises(MotionError):
        sample_into(m, frames, rows, np.asfortranarray(root), q, jt)
    with pytest.raises(MotionError):
        sample_into(m, frames, rows[:3], root, q, jt)


def test_parse_bvh_of_a_few_joints_is_their_part_of_the_whole() -> None:
    whole_motion = _translated_biped()
    data = bvh_text(whole_motion).encode()
    whole = parse_bvh(data)
    names = ["lHand", "lFoot", "no such joint"]
    part = parse_bvh(data, joints=names, name="part")
    kept = part.skeleton.names
    assert set(kept) < set(whole.skeleton.names) and {"lHand", "lFoot", whole.skeleton.names[0]} <= set(kept)
    assert part.units == whole.units and part.fps == whole.fps and part.name == "part"
    assert part.skeleton.end_site_parents.size == 0
    idx = [whole.skeleton.names.index(n) for n in kept]
    np.testing.assert_allclose(part.global_positions(), whole.global_positions()[:, idx], rtol=0, atol=1e-12)
    # a joint with position channels keeps them (the knee of _translated_biped is an ancestor here)
    knee = whole.skeleton.names[2]
    assert knee in kept and part.skeleton.translated_joints.tolist() == [kept.index(knee)]
    # declared units pass through
    assert parse_bvh(data, joints=names, units="cm").units == "cm"
