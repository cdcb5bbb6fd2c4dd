"""Motion-beat analysis (motion/beats.py): synthetic motions with known beats, options, bad input, the
``segue beats`` CLI, and real walks (skipped when ../shared/data is absent)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from motion import Motion, MotionError
from motion import rotations as rot
from motion.beats import MotionBeats, detect_beats, detect_couple_beats, major_joints
from motion.bvh import write_bvh
from motion.io import load_motion
from motion.resample import sample_at
from service.cli import main

from .synthetic import BIPED_NAMES, biped_skeleton

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
WALK = DATA / "bandai-namco" / "dataset-2" / "dataset-2_walk_normal_005.bvh"

FPS = 60.0


def triangle(t: np.ndarray, reversals: np.ndarray, amp: float) -> np.ndarray:
    """A signal moving at constant speed that reverses direction at ``reversals`` (seconds)."""
    knots = np.concatenate(([0.0], reversals, [t[-1] + 1.0]))
    levels = amp * (np.arange(knots.size) % 2 * 2.0 - 1.0)
    return np.interp(t, knots, levels)


def reversing_biped(reversals: np.ndarray, duration: float, fps: float = FPS, seed: int = 0) -> Motion:
    """A biped whose legs, arms and spine swing back and forth, all reversing at ``reversals``
    (seconds): the moments of distinctive directional change, i.e. the beats."""
    frames = int(round(duration * fps)) + 1
    t = np.arange(frames) / fps
    rng = np.random.default_rng(seed)
    swing = triangle(t, reversals, 0.4)
    q = rot.identity((frames, len(BIPED_NAMES)))
    x = np.array([1.0, 0.0, 0.0])
    z = np.array([0.0, 0.0, 1.0])
    for j, axis, gain in ((1, x, 1.0), (4, x, -1.0), (2, x, 0.6), (5, x, -0.6), (7, z, 0.2), (9, z, 0.5)):
        q[:, j] = rot.from_axis_angle(axis, gain * swing + rng.normal(scale=1e-4, size=frames))
    root = np.zeros((frames, 3))
    root[:, 1] = 0.9
    root[:, 2] = 1.2 * t
    return Motion(biped_skeleton(), root, q, fps, units="m", name="reversing-biped")


def interior(times: np.ndarray, lo: float, hi: float) -> np.ndarray:
    return times[(times > lo) & (times < hi)]


def nearest_error(found: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.abs(found[:, None] - truth[None, :]).min(axis=1)


# -- known beats ---------------------------------------------------------------------------------


def test_regular_beats_are_found_at_the_reversals() -> None:
    period = 0.5
    truth = np.arange(0.37, 12.0, period)
    beats = detect_beats(reversing_biped(truth, 12.0))
    assert beats.period_s == pytest.approx(period, rel=0.03)
    assert beats.bpm == pytest.approx(120.0, rel=0.03)
    inner = interior(beats.times_s, 0.5, 11.5)
    assert inner.size >= 20
    err = nearest_error(inner, truth) * FPS
    assert err.max() <= 1.0 and err.mean() <= 0.25
    assert np.all(np.diff(beats.times_s) > 0)
    assert beats.times_s.min() >= 0.0 and beats.times_s.max() <= 12.0


def test_time_warped_beats_follow_the_warp() -> None:
    """Each interval scaled by up to +-15% at random: the beats follow, no rigid grid drift."""
    rng = np.random.default_rng(4)
    intervals = 0.5 * rng.uniform(0.85, 1.15, 26)
    truth = 0.4 + np.concatenate(([0.0], np.cumsum(intervals)))
    duration = float(truth[-1] + 0.4)
    beats = detect_beats(reversing_biped(truth, duration, seed=1))
    inner = interior(beats.times_s, 0.6, duration - 0.6)
    assert inner.size >= 20
    err = nearest_error(inner, truth) * FPS
    assert err.max() <= 1.0 and err.mean() <= 0.25
    # every true interior beat was found
    missed = nearest_error(interior(truth, 0.6, duration - 0.6), beats.times_s) * FPS
    assert missed.max() <= 1.0


def test_candidates_and_frames() -> None:
    truth = np.arange(0.3, 6.0, 0.5)
    beats = detect_beats(reversing_biped(truth, 6.0))
    assert isinstance(beats, MotionBeats)
    assert beats.candidates_s.ndim == 1 and beats.candidates_s.size > beats.times_s.size
    assert np.all(np.diff(beats.candidates_s) >= 0)
    np.testing.assert_allclose(beats.frames(30.0), beats.times_s * 30.0)
    assert beats.times_s.dtype == np.float64 and beats.frames(30.0).dtype == np.float64
    with pytest.raises(MotionError, match="fps"):
        beats.frames(0.0)
    assert 0.0 <= beats.phase_s < beats.period_s


# -- options -------------------------------------------------------------------------------------


def test_joint_restriction_and_positions() -> None:
    truth = np.arange(0.3, 8.0, 0.5)
    m = reversing_biped(truth, 8.0)
    for kwargs in ({"joints": ["lThigh", "rThigh"]}, {"joints": [1, 4, 2]}, {"use_positions": True}):
        beats = detect_beats(m, **kwargs)  # type: ignore[arg-type]
        assert beats.period_s == pytest.approx(0.5, rel=0.05), kwargs
        err = nearest_error(interior(beats.times_s, 0.5, 7.5), truth) * FPS
        assert err.max() <= 1.0, kwargs


def test_tempo_prior_bounds_the_period() -> None:
    truth = np.arange(0.3, 10.0, 0.5)  # 120 bpm
    m = reversing_biped(truth, 10.0)
    assert detect_beats(m, tempo_bpm=(100.0, 140.0)).bpm == pytest.approx(120.0, rel=0.03)
    slow = detect_beats(m, tempo_bpm=(40.0, 90.0))  # the true tempo is excluded
    assert 40.0 <= slow.bpm <= 90.0


def test_bad_joints_raise() -> None:
    m = reversing_biped(np.arange(0.3, 3.0, 0.5), 3.0)
    with pytest.raises(MotionError, match="unknown joint"):
        detect_beats(m, joints=["nope"])
    with pytest.raises(MotionError, match="out of range"):
        detect_beats(m, joints=[99])
    with pytest.raises(MotionError, match="non-empty"):
        detect_beats(m, joints=[])
    with pytest.raises(MotionError, match="non-empty"):
        detect_beats(m, joints="lThigh")


def test_major_joints_by_name() -> None:
    names = ["Hips", "Spine", "LeftUpLeg", "LeftToeBase", "RightHandIndex1", "Head", "LeftEye", "lShin"]
    assert [names[i] for i in major_joints(names)] == ["Hips", "Spine", "LeftUpLeg", "Head", "lShin"]


def test_couple_beats_share_one_clock() -> None:
    truth = np.arange(0.3, 8.0, 0.5)
    lead, follow = reversing_biped(truth, 8.0, seed=1), reversing_biped(truth, 8.0, seed=2)
    beats = detect_couple_beats([lead, follow])
    assert beats.bpm == pytest.approx(120.0, rel=0.03)
    err = nearest_error(interior(beats.times_s, 0.5, 7.5), truth) * FPS
    assert err.max() <= 1.0
    with pytest.raises(MotionError, match="share fps and frame count"):
        detect_couple_beats([lead, lead.slice(0, 300)])
    with pytest.raises(MotionError, match="at least one"):
        detect_couple_beats([])


# -- bad input -----------------------------------------------------------------------------------


def test_too_short_raises() -> None:
    m = reversing_biped(np.array([0.02]), 5 / FPS)
    with pytest.raises(MotionError, match="too short"):
        detect_beats(m)
    # long enough in frames but not for two beats of the fastest tempo
    m = reversing_biped(np.array([0.1]), 0.4)
    with pytest.raises(MotionError, match="too short"):
        detect_beats(m, tempo_bpm=(40.0, 200.0))


@pytest.mark.parametrize(
    "tempo", [(120.0, 60.0), (0.0, 100.0), (-10.0, 100.0), (40.0, float("nan")), (40.0, 5000.0)]
)
def test_absurd_tempo_raises(tempo: tuple[float, float]) -> None:
    m = reversing_biped(np.arange(0.3, 3.0, 0.5), 3.0)
    with pytest.raises(MotionError, match="tempo_bpm"):
        detect_beats(m, tempo_bpm=tempo)


def test_tempo_must_be_a_pair() -> None:
    m = reversing_biped(np.arange(0.3, 3.0, 0.5), 3.0)
    with pytest.raises(MotionError, match="pair"):
        detect_beats(m, tempo_bpm=(60.0,))  # type: ignore[arg-type]


def test_still_motion_gets_the_slowest_grid() -> None:
    m = reversing_biped(np.array([100.0]), 4.0)
    f = m.num_frames
    still = Motion(m.skeleton, np.repeat(m.root_positions[:1], f, 0), np.repeat(m.rotations[:1], f, 0), m.fps)
    beats = detect_beats(still)
    assert beats.bpm == pytest.approx(40.0)
    assert np.all(np.isfinite(beats.times_s)) and beats.candidates_s.size == 0


# -- CLI -----------------------------------------------------------------------------------------


def test_cli_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth = np.arange(0.3, 6.0, 0.5)
    path = tmp_path / "walk.bvh"
    write_bvh(reversing_biped(truth, 6.0), path)
    assert main(["beats", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert {"period_s", "bpm", "beats_s"} <= set(out)
    assert out["bpm"] == pytest.approx(120.0, rel=0.05)
    assert out["period_s"] == pytest.approx(60.0 / out["bpm"], rel=1e-4)
    err = nearest_error(interior(np.array(out["beats_s"]), 0.5, 5.5), truth) * FPS
    assert err.max() <= 1.0
    assert main(["beats", str(path), "--tempo", "40:90", "--joints", "lThigh,rThigh", "--positions"]) == 0
    text = capsys.readouterr().out
    assert "bpm" in text and "beats" in text


def test_cli_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "walk.bvh"
    write_bvh(reversing_biped(np.arange(0.3, 3.0, 0.5), 3.0), path)
    assert main(["beats", str(path), "--tempo", "fast"]) == 2
    assert "LOW:HIGH" in capsys.readouterr().err
    assert main(["beats", str(path), "--tempo", "90:40"]) == 2
    assert "tempo_bpm" in capsys.readouterr().err
    assert main(["beats", str(path), "--joints", "nope"]) == 2
    assert "unknown joint" in capsys.readouterr().err
    assert main(["beats", str(tmp_path / "missing.bvh")]) == 2


# -- real data -----------------------------------------------------------------------------------


@pytest.mark.skipif(not WALK.is_file(), reason=f"shared data not found: {WALK}")
def test_real_walk_step_beats_survive_a_time_warp() -> None:
    """A Bandai walk: beats are steps (90-140 bpm) and stay on the same poses when the clip is played
    13% slower (resampled, then labelled with the original rate)."""
    walk = load_motion(WALK)
    beats = detect_beats(walk)
    assert 90.0 <= beats.bpm <= 140.0
    gaps = np.diff(beats.times_s)
    assert np.median(gaps) == pytest.approx(beats.period_s, rel=0.15)
    factor = 1.13
    n = int((walk.num_frames - 1) * factor) + 1
    slow = sample_at(walk, np.arange(n) / factor)
    slow_beats = detect_beats(slow)
    expected = beats.times_s * factor
    inner = interior(slow_beats.times_s, 0.5, slow.duration_s - 0.5)
    err = nearest_error(inner, expected) * walk.fps
    assert inner.size >= 8 and err.max() <= 1.0 and err.mean() <= 0.25
