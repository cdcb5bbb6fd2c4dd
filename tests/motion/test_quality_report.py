"""The quality report (motion.quality, motion.goals, motion.plausibility): measured on the motion,
each goal with `satisfied`, physical plausibility against examples, one `ok` with reasons."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from motion import Motion, read_bvh
from motion.goals import (
    BeatGoal,
    BodyGoal,
    Character,
    JointGoal,
    LabelGoal,
    LengthGoal,
    ObstacleGoal,
    PathGoal,
    PoseGoal,
    body_pose,
    body_track,
)
from motion.metrics import beat_align_scores
from motion.plausibility import Reference, profile, reference_from_positions
from motion.quality import QualityInputs, assess
from motion.regions import FloorRegion
from motion.samples import sample_path

from .synthetic import walking_biped


def reference_of(*motions: Motion) -> Reference:
    return reference_from_positions([(m.global_positions(), m.skeleton, m.fps) for m in motions])


@pytest.fixture(scope="module")
def walk() -> Motion:
    return walking_biped(frames=240, fps=30.0, speed=1.2)


@pytest.fixture(scope="module")
def ref(walk: Motion) -> Reference:
    return reference_of(walk, walking_biped(frames=240, fps=30.0, speed=1.0, seed=1))


def test_examples_pass_their_own_plausibility(walk: Motion, ref: Reference) -> None:
    report = assess(walk, QualityInputs(goals=(LengthGoal(240),)), ref)
    assert report.ok, report.reasons
    assert report.constraint_errors["length"] == {"frames": 0, "asked": 240, "got": 240, "satisfied": True}
    assert report.plausibility["root_speed"]["value"] == pytest.approx(1.2, abs=0.02)
    assert report.plausibility["root_speed"]["ratio"] == pytest.approx(1.0, abs=0.01)
    assert report.metrics["root_speed_max_m_s"] == report.plausibility["root_speed"]["value"]


def test_a_dragged_body_is_caught(walk: Motion, ref: Reference) -> None:
    """The legs walk at 1.2 m/s while the body is pulled along at 4 m/s: the root speed and the
    planted foot (the lowest foot, whatever its speed) both say so."""
    t = np.arange(walk.num_frames) / walk.fps
    root = walk.root_positions.copy()
    root[:, 2] += 2.8 * t  # 2.8 m/s more
    dragged = replace(walk, root_positions=root)
    report = assess(dragged, None, ref)
    assert not report.ok
    assert not report.plausibility["root_speed"]["ok"] and report.plausibility["root_speed"]["ratio"] > 3
    assert not report.plausibility["foot_slide"]["ok"]
    assert report.plausibility["foot_slide"]["value"] > 2.0
    assert any("peak speed" in r for r in report.reasons) and any("planted foot" in r for r in report.reasons)


def test_a_teleporting_root_is_caught(ref: Reference) -> None:
    """Bandai-style rig: a static root joint (joint 0) that jumps 19 m in one frame while the
    body is continuous (the other joints' global positions unchanged)."""
    m = read_bvh(sample_path("walk")).slice(1, 120).to_units("m")
    root = m.root_positions.copy()
    root[60:, 0] += 19.0
    jumped = replace(m, root_positions=root)
    own = reference_of(m)
    report = assess(jumped, None, own)
    step = report.plausibility["joint_step"]
    assert not step["ok"] and step["value"] > 18 and step["frame"] == 60
    assert any("one-frame joint step" in r for r in report.reasons)
    assert assess(m, None, own).plausibility["joint_step"]["ok"]


def test_body_goal_met_missed_and_unreachable(walk: Motion, ref: Reference) -> None:
    xz, yaw = body_track(walk.global_positions(), walk.skeleton)
    assert yaw is not None
    met = BodyGoal("body[1]", 100, xz[100], float(yaw[100]))
    off = BodyGoal("body[2]", 100, xz[100] + [0.3, 0.4], float(yaw[100]) + np.radians(20))
    far = BodyGoal("body[3]", 239, np.array([0.0, 500.0]))
    report = assess(walk, QualityInputs(goals=(met, off, far)), ref)
    e = report.constraint_errors
    assert e["body[1]"]["satisfied"] and e["body[1]"]["position_cm"] < 1e-6
    assert e["body[2]"]["position_cm"] == pytest.approx(50.0, abs=1e-3)
    assert e["body[2]"]["heading_deg"] == pytest.approx(20.0, abs=1e-3)
    assert not e["body[2]"]["satisfied"] and e["body[2]"]["tolerance_cm"] == 5.0
    assert not e["body[3]"]["satisfied"] and "reachable" in " ".join(report.reasons)
    assert e["body[3]"]["reachable_m"] == pytest.approx(ref.root_speed_max * 239 / 30, rel=1e-3)
    assert not report.ok and len(report.reasons) == 2


def test_joint_pose_path_and_obstacle_goals(walk: Motion, ref: Reference) -> None:
    pos = walk.global_positions()
    head = walk.skeleton.index("head")
    xz, _ = body_track(pos, walk.skeleton)
    goals = (
        JointGoal("joint[0]", 50, head, pos[50, head] + [0.0, 0.03, 0.0]),
        JointGoal("joint[1]", 50, head, pos[50, head], velocity=np.array([0.0, 0.0, 5.0])),
        PoseGoal("pose[0]", 80, body_pose(pos[80:81], walk.skeleton)[0], extra={"held": True}),
        PathGoal("path", np.arange(240), xz + np.array([0.02, 0.0])),
        ObstacleGoal("obstacle[0]", FloorRegion.disc(xz[120], 0.3)),
        ObstacleGoal("obstacle[1]", FloorRegion.from_polygon([[5, 5], [6, 5], [6, 6]])),
    )
    e = assess(walk, QualityInputs(goals=goals), ref).constraint_errors
    assert e["joint[0]"]["position_cm"] == pytest.approx(3.0, abs=1e-6) and e["joint[0]"]["satisfied"]
    assert not e["joint[1]"]["satisfied"] and e["joint[1]"]["velocity_cm_s"] > 300
    assert e["pose[0]"]["pose_cm"] < 1e-6 and e["pose[0]"]["held"] and e["pose[0]"]["satisfied"]
    assert e["path"]["rms_cm"] == pytest.approx(2.0, abs=1e-6) and e["path"]["satisfied"]
    assert not e["obstacle[0]"]["satisfied"] and e["obstacle[0]"]["depth_cm"] == pytest.approx(30, abs=1)
    assert e["obstacle[1]"] == {"frames": 0, "depth_cm": 0.0, "tolerance_cm": 0.0, "satisfied": True}


def test_label_goal_counts_frames_away_from_transitions() -> None:
    honoured = np.ones(100, dtype=bool)
    honoured[:15] = False  # the transition into the range
    goal = LabelGoal("label[0]", "run", 100, 200, 1, honoured, margin=15)
    m = walking_biped(frames=220)
    e = assess(m, QualityInputs(goals=(goal,))).constraint_errors["label[0]"]
    assert e["frames"] == 15 and e["honoured"] == 1.0 and e["satisfied"]
    strict = replace(goal, margin=0)
    e = assess(m, QualityInputs(goals=(strict,))).constraint_errors["label[0]"]
    assert e["honoured"] == pytest.approx(0.85) and not e["satisfied"]


def test_beat_goal_and_characters(walk: Motion) -> None:
    """Two characters side by side: every figure is the worst character's; beats are scored for
    each."""
    from motion.skeleton import Skeleton

    sk = walk.skeleton
    j = sk.num_joints
    names = ("world", *(f"a_{n}" for n in sk.names), *(f"b_{n}" for n in sk.names))
    parents = np.concatenate(([-1, 0], sk.parents[1:] + 1, [0], sk.parents[1:] + 1 + j))
    combined = Skeleton(
        names,
        parents,
        np.concatenate((np.zeros((1, 3)), sk.offsets, sk.offsets)),
        (("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),) + sk.channels * 2,
    )
    slow = walking_biped(frames=240, fps=30.0, speed=0.6, seed=3)
    rot = np.concatenate((walk.rotations[:, :1] * 0 + [0, 0, 0, 1], walk.rotations, slow.rotations), axis=1)
    root = np.zeros((240, 3))
    jt = np.stack((walk.root_positions, slow.root_positions + np.array([2.0, 0, 0])), axis=1)
    # each character's hips carries its translation (a translated joint under the static world)
    both = Motion(combined, root, rot, 30.0, jt, "m")
    chars = (Character(np.arange(1, 1 + j), sk, "a"), Character(np.arange(1 + j, 1 + 2 * j), sk, "b"))
    beats = np.arange(0, 8.0, 0.5)
    report = assess(both, QualityInputs(goals=(BeatGoal("music", beats),), characters=chars))
    assert report.plausibility["root_speed"]["character"] == 0
    assert report.plausibility["root_speed"]["value"] == pytest.approx(1.2, abs=0.02)
    music = report.constraint_errors["music"]
    assert set(music) >= {"beat_align_mint", "beat_align_bailando", "satisfied", "character"}
    alone = beat_align_scores(slow.global_positions(), 30.0, beats)
    per = [beat_align_scores(both.global_positions()[:, c.joints], 30.0, beats) for c in chars]
    assert per[1][0] == pytest.approx(alone[0])
    worst = min(range(2), key=lambda i: min(per[i][0], per[i][1]))
    assert music["character"] == worst


def test_profile_and_reference_round_trip(walk: Motion, ref: Reference) -> None:
    p = profile(walk.global_positions(), walk.skeleton, walk.fps)
    assert p.root_speed.size == 240 - 5 and p.foot_speed.size == 239
    assert ref.clips == 2 and ref.root_speed_max == pytest.approx(1.2, abs=0.02)
    assert Reference.from_arrays(ref.to_arrays()) == ref
    assert Reference.from_arrays({}) is None


def test_beat_align_scores_count_speed_minima() -> None:
    fps, period = 60.0, 0.5
    t = np.arange(int(6 * fps)) / fps
    # one moving point whose speed dips to zero at every music beat (0, 0.5, 1.0, ...)
    x = t - np.sin(2 * np.pi * t / period) * period / (2 * np.pi)
    pos = np.stack((x, np.zeros_like(x), np.zeros_like(x)), axis=-1)[:, None, :]
    music = np.arange(0, 6.0, period)
    mint, bail, minima = beat_align_scores(pos, fps, music)
    assert mint > 0.85 and bail > 0.85 and minima.size >= 8
    mint2, bail2, _ = beat_align_scores(pos, fps, music + period / 2)  # music off by half a beat
    assert mint2 < 0.01 and bail2 < 0.01


def test_the_fastest_foot_against_the_examples(walk: Motion, ref: Reference) -> None:
    """The report gives the fastest foot (frame to frame) against the examples' fastest: a knee
    that turns half round for one frame snaps its foot, 1.3 times the examples' or more."""
    from dataclasses import replace

    from motion import rotations as rot
    from motion.contacts import foot_joints

    report = assess(walk, QualityInputs(), ref)
    speed = report.plausibility["foot_speed"]
    assert speed["ratio"] <= 1.0 + 1e-9 and speed["limit"] is None  # reported, not gated
    assert report.metrics["foot_speed_ratio"] == speed["ratio"]
    foot = int(foot_joints(walk.skeleton)[0])
    knee = int(walk.skeleton.parents[foot])
    q = np.array(walk.rotations, copy=True)
    q[120, knee] = rot.multiply(rot.from_axis_angle(np.array([1.0, 0.0, 0.0]), 1.2), q[120, knee])
    snapped = assess(replace(walk, rotations=q), QualityInputs(), ref).plausibility["foot_speed"]
    assert snapped["ratio"] > 1.3 and snapped["value"] > snapped["snap_limit"]
    assert snapped["frame"] in (120, 121)
