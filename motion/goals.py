"""What a request asked of a motion, and how far the motion is from it.

Each goal is a small frozen dataclass an engine builds from its request (engine-independent
terms: output frames, joint indices of the output skeleton, floor positions ``[x, z]`` metres,
headings in radians about +Y); :func:`measure` measures it on the returned motion's joint
positions and says whether it is ``satisfied`` against its stated tolerance. The entry keys are
those of the report's ``constraint_errors`` (``body[1]``: ``frame``, ``position_cm``,
``heading_deg``, ``satisfied``, ``tolerance_cm``, ``tolerance_deg``...).

Defaults follow Arikan & Forsyth 2002, who report body and joint constraints met within 5 cm and
5 degrees.
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from .contacts import foot_joints
from .errors import MotionError
from .ground import body_joints, body_root, facing_from_positions, to_ground_frame
from .metrics import beat_align_scores
from .regions import FloorRegion
from .skeleton import Skeleton

Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

POSITION_TOLERANCE_CM = 5.0
HEADING_TOLERANCE_DEG = 5.0
VELOCITY_TOLERANCE_CM_S = 20.0
LABEL_MIN_FRACTION = 0.9
BEAT_MIN_SCORE = 0.5


@dataclass(frozen=True, slots=True)
class Character:
    """One character of an output: its joints (indices into the output skeleton, in the order of
    ``skeleton``, the character's own skeleton used to find its hips, feet and facing) and a
    label for messages."""

    joints: npt.NDArray[np.intp]
    skeleton: Skeleton
    label: str = ""


@dataclass(frozen=True, slots=True)
class LengthGoal:
    """The output should have ``frames`` frames."""

    frames: int
    name: str = "length"


@dataclass(frozen=True, slots=True)
class BodyGoal:
    """The body (hips on the floor, facing) at ``xz`` (metres) facing ``heading`` (radians, or
    free) at output ``frame``."""

    name: str
    frame: int
    xz: Array
    heading: float | None = None
    character: int = 0
    tolerance_cm: float = POSITION_TOLERANCE_CM
    tolerance_deg: float = HEADING_TOLERANCE_DEG


@dataclass(frozen=True, slots=True)
class JointGoal:
    """Output joint ``joint`` (an index of the output skeleton) at ``position (3,)`` metres, and
    moving at ``velocity (3,)`` m/s when given, at output ``frame``."""

    name: str
    frame: int
    joint: int
    position: Array
    velocity: Array | None = None
    tolerance_cm: float = POSITION_TOLERANCE_CM
    tolerance_cm_s: float = VELOCITY_TOLERANCE_CM_S


@dataclass(frozen=True, slots=True)
class PoseGoal:
    """A whole pose at output ``frame``: ``pose (J, 3)`` joint positions (metres) of the
    character's skeleton in the body's ground frame (:func:`body_pose`), e.g. a clip's frame;
    the body's joints are compared (:func:`motion.ground.body_joints`: not a static reference
    joint above the hips, which stays put wherever the body goes). ``extra`` entries (how the
    engine placed it) are copied into the report."""

    name: str
    frame: int
    pose: Array
    character: int = 0
    tolerance_cm: float = POSITION_TOLERANCE_CM
    extra: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class ObstacleGoal:
    """The body root and the feet of every character (or of the ``characters`` listed) stay out
    of a floor region."""

    name: str
    region: FloorRegion
    tolerance_cm: float = 0.0
    characters: tuple[int, ...] | None = None


@dataclass(frozen=True, slots=True)
class LabelGoal:
    """Output frames ``[start, end)`` should carry (``value`` 1) or not carry (-1) ``label``;
    ``honoured (end - start,)`` says, per frame, whether the frame played there does (its source
    frame's labels). Frames within ``margin`` of either end (transitions) are not counted for
    ``satisfied``, which needs ``min_fraction`` of the rest honoured."""

    name: str
    label: str
    start: int
    end: int
    value: int
    honoured: BoolArray
    margin: int = 0
    min_fraction: float = LABEL_MIN_FRACTION


@dataclass(frozen=True, slots=True)
class PathGoal:
    """The body should follow a floor path: ``xz (P, 2)`` metres at output ``frames (P,)``."""

    name: str
    frames: npt.NDArray[np.intp]
    xz: Array
    character: int = 0
    tolerance_cm: float = POSITION_TOLERANCE_CM


@dataclass(frozen=True, slots=True)
class BeatGoal:
    """The motion's beats should land on the music's ``beats_s (B,)`` seconds: both published
    beat-align scores (:func:`motion.metrics.beat_align_scores`) at least ``min_score`` for every
    character."""

    name: str
    beats_s: Array
    min_score: float = BEAT_MIN_SCORE


@dataclass(frozen=True, slots=True)
class LoopGoal:
    """The clip should loop: its last frame's pose equal to its first frame's, root-relative (in
    the body's ground frame, :func:`body_pose`, so root travel and heading may continue), every
    body joint (:func:`motion.ground.body_joints`) of every character within ``tolerance_cm``."""

    name: str = "loop"
    tolerance_cm: float = POSITION_TOLERANCE_CM


@dataclass(frozen=True, slots=True)
class Point:
    """A point of one character of the output: joint ``joint`` (an index of the output
    skeleton), or, when ``joint`` is ``None``, the body of character ``character`` (the hips'
    floor projection). ``label`` names it in messages (``c0.RightHand``)."""

    character: int
    joint: int | None = None
    label: str = ""


@dataclass(frozen=True, slots=True)
class MeetGoal:
    """Shared between two characters: points ``a`` and ``b`` are ``distance_m`` metres apart at
    output ``frame`` (joint to joint: 3-D distance; with a body: floor distance)."""

    name: str
    frame: int
    a: Point
    b: Point
    distance_m: float = 0.0
    tolerance_cm: float = POSITION_TOLERANCE_CM


@dataclass(frozen=True, slots=True)
class ApartGoal:
    """Shared between two characters: points ``a`` and ``b`` stay at least ``min_m`` metres apart
    over output frames ``[start, end)`` (``end`` None: to the last frame); distances as for
    :class:`MeetGoal`. ``tolerance_cm``: how far below ``min_m`` still counts as apart."""

    name: str
    a: Point
    b: Point
    min_m: float
    start: int = 0
    end: int | None = None
    tolerance_cm: float = 0.0


HOLD_MIN_FRACTION = 0.5


@dataclass(frozen=True, slots=True)
class HoldGoal:
    """Shared between two characters over the whole output: points ``a`` and ``b`` (a hand
    hold) within ``max_m`` metres of each other in at least ``min_fraction`` of the frames;
    ``extra`` entries (e.g. what the examples do) are copied into the report."""

    name: str
    a: Point
    b: Point
    max_m: float
    min_fraction: float = HOLD_MIN_FRACTION
    extra: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class HandholdGoal:
    """At output ``frames (n,)`` the character holds a partner's hand (an annotation the engine
    carried over from its examples): one of the output's ``joints`` (its hands) within
    ``tolerance_cm`` of one of ``partner (n, H, 3)`` (the partner's hands there, metres).
    Frames within ``margin`` of either end of a run of consecutive frames (the hands joining or
    letting go) are not counted for ``satisfied``, which needs ``min_fraction`` of the rest held.
    The partner is outside the output (the control engine's leader, given as input); for two
    characters of one output see :class:`HoldGoal`."""

    name: str
    frames: npt.NDArray[np.intp]
    joints: npt.NDArray[np.intp]
    partner: Array
    tolerance_cm: float = 20.0
    margin: int = 0
    min_fraction: float = LABEL_MIN_FRACTION


@dataclass(frozen=True, slots=True)
class FootplantGoal:
    """The feet stay where the examples plant them (an annotation the engine carried over to the
    output frames, Hsu et al. 2004 Sec. 5): over the frames where ``contacts (F, K)`` flags joint
    ``joints[k]`` planted, that joint's mean horizontal speed (m/s), at most ``tolerance_m_s``
    (e.g. the examples' own figure on their contacts). Speeds are taken over ``step_s`` (default
    1/30 s, every frame of the interval planted), so that capture noise at high frame rates does
    not count as sliding."""

    name: str
    joints: npt.NDArray[np.intp]
    contacts: BoolArray
    tolerance_m_s: float
    step_s: float = 1.0 / 30.0


Goal = (
    LengthGoal
    | BodyGoal
    | JointGoal
    | PoseGoal
    | ObstacleGoal
    | LabelGoal
    | PathGoal
    | BeatGoal
    | MeetGoal
    | ApartGoal
    | HoldGoal
    | LoopGoal
    | HandholdGoal
    | FootplantGoal
)


def body_track(positions: Array, skeleton: Skeleton) -> tuple[Array, Array | None]:
    """The body's floor position ``(F, 2)`` (the hips' projection) and heading ``(F,)`` radians
    (``None`` without left/right joints) from one character's joint positions ``(F, J, 3)``."""
    return positions[:, body_root(skeleton)][:, [0, 2]], facing_from_positions(skeleton, positions)


def body_pose(positions: Array, skeleton: Skeleton) -> Array:
    """``(F, J, 3)`` joint positions in each frame's body ground frame (origin under the hips,
    +Z along the heading), the frame poses are compared in."""
    xz, yaw = body_track(positions, skeleton)
    return to_ground_frame(positions, xz, np.zeros(positions.shape[0]) if yaw is None else yaw)


def _deg(a: float) -> float:
    return float(np.degrees(abs((a + np.pi) % (2 * np.pi) - np.pi)))


def _r(x: float) -> float:
    return round(float(x), 4)


def measure(
    goal: Goal,
    positions: Array,
    fps: float,
    characters: Sequence[Character],
    reachable_m_s: float | None = None,
) -> tuple[dict[str, Any], str | None]:
    """Measure one goal on ``positions (F, J, 3)`` (metres, the whole output) at ``fps``.

    Returns the report entry and, when the goal is not satisfied, a one-line reason. With
    ``reachable_m_s`` (the fastest example's speed), an unmet body goal says how far the body
    could have gone."""
    n = positions.shape[0]
    if isinstance(goal, BodyGoal | JointGoal | PoseGoal | MeetGoal) and not 0 <= goal.frame < n:
        e = {"frame": goal.frame, "position_cm": None, "missing": True, "satisfied": False}
        return e, f"{goal.name}: frame {goal.frame} is beyond the motion's {n} frames"
    if isinstance(goal, BodyGoal):
        return _measure_body(goal, positions, fps, characters, reachable_m_s)
    if isinstance(goal, LengthGoal):
        return _measure_length(goal, positions, fps, characters)
    if isinstance(goal, JointGoal):
        return _measure_joint(goal, positions, fps, characters)
    if isinstance(goal, PoseGoal):
        return _measure_pose(goal, positions, fps, characters)
    if isinstance(goal, ObstacleGoal):
        return _measure_obstacle(goal, positions, fps, characters)
    if isinstance(goal, LabelGoal):
        return _measure_label(goal, positions, fps, characters)
    if isinstance(goal, PathGoal):
        return _measure_path(goal, positions, fps, characters)
    if isinstance(goal, BeatGoal):
        return _measure_beats(goal, positions, fps, characters)
    if isinstance(goal, LoopGoal):
        return _measure_loop(goal, positions, fps, characters)
    if isinstance(goal, MeetGoal):
        return _measure_meet(goal, positions, characters)
    if isinstance(goal, ApartGoal):
        return _measure_apart(goal, positions, characters)
    if isinstance(goal, HoldGoal):
        return _measure_hold(goal, positions, characters)
    if isinstance(goal, HandholdGoal):
        return _measure_handhold(goal, positions)
    if isinstance(goal, FootplantGoal):
        return _measure_footplants(goal, positions, fps)
    raise MotionError(f"unknown goal {goal!r}")  # pragma: no cover - the union is closed


Measured = tuple[dict[str, Any], str | None]
"""A goal's report entry and, when it is not satisfied, the one-line reason."""


def _measure_length(
    goal: LengthGoal, positions: Array, fps: float, characters: Sequence[Character]
) -> Measured:
    """Frames of the output against the asked length."""
    n = positions.shape[0]
    ok = n == goal.frames
    e: dict[str, Any] = {"frames": abs(n - goal.frames), "asked": goal.frames, "got": n, "satisfied": ok}
    return e, None if ok else f"length: {n} frames, asked for {goal.frames}"


def _measure_body(
    goal: BodyGoal, positions: Array, fps: float, characters: Sequence[Character], reachable_m_s: float | None
) -> Measured:
    """Floor position (cm) and heading (degrees) of a character's body at a frame; an unmet goal
    says how far the body could have gone at ``reachable_m_s``."""
    pos, sk = _character(goal, positions, characters)
    xz, yaw = body_track(pos, sk)
    dist = float(np.linalg.norm(xz[goal.frame] - goal.xz))
    e = {"frame": goal.frame, "position_cm": _r(100 * dist), "tolerance_cm": goal.tolerance_cm}
    ok = 100 * dist <= goal.tolerance_cm
    why = [f"{100 * dist:.1f} cm from its goal"] if not ok else []
    if goal.heading is not None:
        if yaw is None:
            raise MotionError(f"{goal.name}: the skeleton has no left/right joints to measure a heading")
        herr = _deg(float(yaw[goal.frame]) - goal.heading)
        e.update(heading_deg=_r(herr), tolerance_deg=goal.tolerance_deg)
        if herr > goal.tolerance_deg:
            ok = False
            why.append(f"{herr:.1f} deg off its heading")
    e["satisfied"] = ok
    if ok:
        return e, None
    reason = f"{goal.name} (frame {goal.frame}): " + " and ".join(why)
    reason += f" (tolerance {goal.tolerance_cm:g} cm / {goal.tolerance_deg:g} deg)"
    if reachable_m_s is not None and reachable_m_s > 0:
        start = xz[0]
        away = float(np.linalg.norm(goal.xz - start))
        reach = reachable_m_s * goal.frame / fps
        if away > reach:
            reason += f": goal {away:.1f} m away, reachable {reach:.1f} m in {goal.frame + 1} frames"
            e["reachable_m"] = _r(reach)
    return e, reason


def _measure_joint(
    goal: JointGoal, positions: Array, fps: float, characters: Sequence[Character]
) -> Measured:
    """A joint's position (cm) and velocity (cm/s) at a frame."""
    n = positions.shape[0]
    p = positions[goal.frame, goal.joint]
    dist = 100 * float(np.linalg.norm(p - goal.position))
    e = {"frame": goal.frame, "position_cm": _r(dist), "tolerance_cm": goal.tolerance_cm}
    ok = dist <= goal.tolerance_cm
    why = [f"{dist:.1f} cm from its target"] if not ok else []
    if goal.velocity is not None:
        a, b = max(goal.frame - 1, 0), min(goal.frame + 1, n - 1)
        v = (positions[b, goal.joint] - positions[a, goal.joint]) * fps / max(b - a, 1)
        verr = 100 * float(np.linalg.norm(v - goal.velocity))
        e.update(velocity_cm_s=_r(verr), tolerance_cm_s=goal.tolerance_cm_s)
        if verr > goal.tolerance_cm_s:
            ok = False
            why.append(f"velocity {verr:.0f} cm/s off")
    e["satisfied"] = ok
    return e, None if ok else f"{goal.name} (frame {goal.frame}): " + " and ".join(why) + (
        f" (tolerance {goal.tolerance_cm:g} cm)"
    )


def _measure_pose(goal: PoseGoal, positions: Array, fps: float, characters: Sequence[Character]) -> Measured:
    """The largest joint distance (cm) from a wanted pose, in the body's ground frame."""
    pos, sk = _character(goal, positions, characters)
    got = body_pose(pos[goal.frame : goal.frame + 1], sk)[0]
    body = body_joints(sk)  # not a static reference joint above the hips: it stays where it is
    err = 100 * float(np.linalg.norm(got[body] - goal.pose[body], axis=-1).max())
    ok = err <= goal.tolerance_cm
    e = {"frame": goal.frame, **dict(goal.extra), "pose_cm": _r(err), "tolerance_cm": goal.tolerance_cm}
    e["satisfied"] = ok
    return e, None if ok else (
        f"{goal.name} (frame {goal.frame}): a joint is {err:.1f} cm from the wanted pose "
        f"(tolerance {goal.tolerance_cm:g} cm)"
    )


def _measure_loop(goal: LoopGoal, positions: Array, fps: float, characters: Sequence[Character]) -> Measured:
    """The largest joint distance (cm) between the last and the first frame's root-relative pose,
    and the root-relative hip height change (cm), over every character."""
    n = positions.shape[0]
    err, mean, rise = 0.0, 0.0, 0.0
    for c in characters:
        pose = body_pose(positions[[0, n - 1]][:, c.joints], c.skeleton)
        body = body_joints(c.skeleton)  # not a static reference joint above the hips
        gap = np.linalg.norm(pose[1, body] - pose[0, body], axis=-1)
        err = max(err, 100 * float(gap.max()))
        mean = max(mean, 100 * float(gap.mean()))
        hips = body_root(c.skeleton)
        rise = max(rise, 100 * abs(float(pose[1, hips, 1] - pose[0, hips, 1])))
    ok = err <= goal.tolerance_cm
    e = {
        "first_frame": 0,
        "last_frame": n - 1,
        "pose_cm": _r(err),
        "mean_cm": _r(mean),
        "hip_height_cm": _r(rise),
        "tolerance_cm": goal.tolerance_cm,
        "satisfied": ok,
    }
    return e, None if ok else (
        f"{goal.name}: the last frame's pose is {err:.1f} cm (a joint) from the first one's "
        f"(tolerance {goal.tolerance_cm:g} cm)"
    )


def _measure_obstacle(
    goal: ObstacleGoal, positions: Array, fps: float, characters: Sequence[Character]
) -> Measured:
    """Frames in which a body root or a foot is inside the region, and how deep (cm)."""
    n = positions.shape[0]
    deepest = np.zeros(n)
    chosen = characters if goal.characters is None else [characters[i] for i in goal.characters]
    for c in chosen:
        pos = positions[:, c.joints]
        pts = [pos[:, body_root(c.skeleton)][:, None, [0, 2]]]
        with contextlib.suppress(MotionError):  # no feet by name: the body root alone
            pts.append(pos[:, foot_joints(c.skeleton)][:, :, [0, 2]])
        deepest = np.maximum(deepest, goal.region.depth(np.concatenate(pts, axis=1)).max(axis=1))
    depth_cm = 100 * float(deepest.max(initial=0.0))
    inside = int(np.count_nonzero(deepest > goal.tolerance_cm / 100 + 1e-9))
    ok = inside == 0
    e = {"frames": inside, "depth_cm": _r(depth_cm), "tolerance_cm": goal.tolerance_cm, "satisfied": ok}
    return e, None if ok else (
        f"{goal.name}: the body or a foot is inside for {inside} frames, {depth_cm:.1f} cm deep"
    )


def _measure_label(
    goal: LabelGoal, positions: Array, fps: float, characters: Sequence[Character]
) -> Measured:
    """The fraction of a window's frames (margins left out) that honour a label."""
    h = np.asarray(goal.honoured, dtype=bool)
    window = goal.end - goal.start
    if h.shape != (window,):
        raise MotionError(f"{goal.name}: {h.shape[0]} honoured flags for a {window}-frame window")
    core = h[goal.margin : window - goal.margin] if window > 2 * goal.margin else h
    fraction = float(core.mean()) if core.size else 1.0
    ok = fraction >= goal.min_fraction
    e = {
        "label": goal.label,
        "value": goal.value,
        "start": goal.start,
        "end": goal.end,
        "frames": int(window - h.sum()),
        "window": window,
        "honoured": _r(fraction),
        "margin": goal.margin,
        "tolerance": goal.min_fraction,
        "satisfied": ok,
    }
    want = "carry" if goal.value > 0 else "avoid"
    return e, None if ok else (
        f"{goal.name}: frames {goal.start}-{goal.end} should {want} {goal.label!r}; "
        f"{100 * fraction:.0f}% do (at least {100 * goal.min_fraction:.0f}%)"
    )


def _measure_path(goal: PathGoal, positions: Array, fps: float, characters: Sequence[Character]) -> Measured:
    """RMS and largest distance (cm) of the body from a floor path."""
    n = positions.shape[0]
    pos, sk = _character(goal, positions, characters)
    xz, _ = body_track(pos, sk)
    f = np.asarray(goal.frames, dtype=np.intp)
    keep = (f >= 0) & (f < n)
    d = np.linalg.norm(xz[f[keep]] - goal.xz[keep], axis=-1) * 100
    rms = float(np.sqrt(np.mean(d**2))) if d.size else 0.0
    ok = bool(keep.all()) and rms <= goal.tolerance_cm
    e = {
        "rms_cm": _r(rms),
        "max_cm": _r(float(d.max(initial=0.0))),
        "frames": int(keep.sum()),
        "tolerance_cm": goal.tolerance_cm,
        "satisfied": ok,
    }
    return e, None if ok else (
        f"{goal.name}: the body is {rms:.1f} cm (RMS) from the path (tolerance {goal.tolerance_cm:g} cm)"
    )


def _measure_handhold(goal: HandholdGoal, positions: Array) -> Measured:
    """The fraction of the annotated frames whose nearest pair of hands (output, partner) is within
    the tolerance, and the median of that distance (cm)."""
    keep = (goal.frames >= 0) & (goal.frames < positions.shape[0])
    if goal.margin > 0 and goal.frames.size:
        # position of each frame in its run of consecutive frames, from the start and from the end
        f = goal.frames
        starts = np.concatenate(([True], np.diff(f) != 1))
        run = np.cumsum(starts) - 1
        first = np.flatnonzero(starts)
        last = np.concatenate((first[1:], [f.size])) - 1
        keep &= (f - f[first[run]] >= goal.margin) & (f[last[run]] - f >= goal.margin)
    if not keep.any():
        return {"frames": 0, "satisfied": True}, None
    own = positions[goal.frames[keep]][:, goal.joints]  # (n, K, 3)
    part = goal.partner[keep]  # (n, H, 3)
    dist = 100 * np.linalg.norm(own[:, :, None] - part[:, None], axis=-1).min(axis=(1, 2))  # (n,) cm
    held = float((dist <= goal.tolerance_cm).mean())
    ok = held >= goal.min_fraction
    e = {
        "frames": int(dist.size),
        "held_fraction": _r(held),
        "median_cm": _r(float(np.median(dist))),
        "tolerance_cm": goal.tolerance_cm,
        "margin_frames": goal.margin,
        "min_fraction": goal.min_fraction,
        "satisfied": ok,
    }
    return e, None if ok else (
        f"{goal.name}: hands within {goal.tolerance_cm:g} cm on {100 * held:.0f}% of the {dist.size} "
        f"frames that hold hands in the examples (wanted {100 * goal.min_fraction:.0f}%; "
        f"median {np.median(dist):.0f} cm)"
    )


def planted_speeds(
    positions: Array, joints: npt.NDArray[np.intp], contacts: BoolArray, fps: float, step_s: float
) -> Array:
    """Horizontal speeds (m/s) of ``joints`` over every interval of ``step_s`` (at least one
    frame) whose frames are all flagged planted in ``contacts (F, K)``; ``positions (F, J, 3)``
    metres at ``fps``. Returns the speeds of every planted (interval, joint), flattened."""
    step = max(1, int(round(step_s * fps)))
    n = min(positions.shape[0], contacts.shape[0])
    if n <= step:
        return np.zeros(0)
    feet = positions[:n, joints][:, :, [0, 2]]  # (n, K, 2)
    speed = np.linalg.norm(feet[step:] - feet[:-step], axis=-1) * (fps / step)  # (n - step, K)
    # every frame of [t, t + step] planted: a window count over the flags
    flags = np.asarray(contacts[:n], dtype=np.int64)
    counts: npt.NDArray[np.int64] = np.concatenate(
        (np.zeros((1, flags.shape[1]), np.int64), np.cumsum(flags, axis=0))
    )
    planted = counts[step + 1 :] - counts[: n - step] == step + 1
    return np.asarray(speed[planted])


def _measure_footplants(goal: FootplantGoal, positions: Array, fps: float) -> Measured:
    """The feet's mean horizontal speed where the carried-over contacts plant them."""
    speeds = planted_speeds(positions, goal.joints, goal.contacts, fps, goal.step_s)
    if speeds.size == 0:
        return {"frames": 0, "satisfied": True}, None
    slide = float(speeds.mean())
    ok = slide <= goal.tolerance_m_s
    e = {
        "frames": int(speeds.size),
        "slide_m_s": _r(slide),
        "p90_m_s": _r(float(np.percentile(speeds, 90))),
        "tolerance_m_s": _r(goal.tolerance_m_s),
        "satisfied": ok,
    }
    return e, None if ok else (
        f"{goal.name}: the feet slide {slide:.2f} m/s where the examples plant them "
        f"({speeds.size} foot-frames; tolerance {goal.tolerance_m_s:.2f} m/s)"
    )


def _measure_beats(goal: BeatGoal, positions: Array, fps: float, characters: Sequence[Character]) -> Measured:
    """Beat alignment scores (mint and Bailando) of the worst character."""
    scores = [beat_align_scores(positions[:, c.joints], fps, goal.beats_s)[:2] for c in characters]
    mint = [s[0] for s in scores]
    bail = [s[1] for s in scores]
    worst = int(np.argmin(np.minimum(mint, bail)))
    ok = min(mint[worst], bail[worst]) >= goal.min_score
    e = {
        "beat_align_mint": _r(mint[worst]),
        "beat_align_bailando": _r(bail[worst]),
        "beat_align_mint_mean": _r(float(np.mean(mint))),
        "beat_align_bailando_mean": _r(float(np.mean(bail))),
        "beats": int(goal.beats_s.size),
        "character": worst,
        "tolerance": goal.min_score,
        "satisfied": ok,
    }
    return e, None if ok else (
        f"{goal.name}: beat alignment {mint[worst]:.2f} (mint) / {bail[worst]:.2f} (Bailando), "
        f"at least {goal.min_score:g} asked"
    )


def _character(
    goal: BodyGoal | PoseGoal | PathGoal, positions: Array, characters: Sequence[Character]
) -> tuple[Array, Skeleton]:
    """``(F, J_c, 3)`` positions and the skeleton of the goal's character."""
    i = goal.character
    if not 0 <= i < len(characters):
        raise MotionError(f"{goal.name}: character {i} is not in the output")
    c = characters[i]
    return positions[:, c.joints], c.skeleton


def point_track(point: Point, positions: Array, characters: Sequence[Character]) -> Array:
    """``(F, 3)`` metres: the point's joint positions, or its character's body on the floor
    (the hips' projection, ``y`` 0)."""
    if point.joint is not None:
        if not 0 <= point.joint < positions.shape[1]:
            raise MotionError(f"{point.label or 'point'}: joint {point.joint} is not in the output")
        return np.asarray(positions[:, point.joint], dtype=np.float64)
    if not 0 <= point.character < len(characters):
        raise MotionError(f"{point.label or 'point'}: character {point.character} is not in the output")
    c = characters[point.character]
    hips = positions[:, c.joints[body_root(c.skeleton)]]
    return np.stack((hips[:, 0], np.zeros(hips.shape[0]), hips[:, 2]), axis=-1)


def point_distance(a: Point, b: Point, positions: Array, characters: Sequence[Character]) -> Array:
    """``(F,)`` metres between two points: 3-D between two joints, on the floor when either is a
    body."""
    pa, pb = point_track(a, positions, characters), point_track(b, positions, characters)
    d = pa - pb
    if a.joint is None or b.joint is None:
        d = d[:, [0, 2]]
    return np.asarray(np.linalg.norm(d, axis=-1))


def _measure_meet(goal: MeetGoal, positions: Array, characters: Sequence[Character]) -> Measured:
    """The distance (cm) between the two points at the frame, against the wanted one."""
    d = float(point_distance(goal.a, goal.b, positions[goal.frame : goal.frame + 1], characters)[0])
    err = 100 * abs(d - goal.distance_m)
    ok = err <= goal.tolerance_cm
    e = {
        "frame": goal.frame,
        "a": goal.a.label,
        "b": goal.b.label,
        "distance_cm": _r(100 * d),
        "wanted_cm": _r(100 * goal.distance_m),
        "error_cm": _r(err),
        "tolerance_cm": goal.tolerance_cm,
        "satisfied": ok,
    }
    return e, None if ok else (
        f"{goal.name} (frame {goal.frame}): {goal.a.label} and {goal.b.label} are {100 * d:.1f} cm apart, "
        f"{err:.1f} cm from the wanted {100 * goal.distance_m:g} cm (tolerance {goal.tolerance_cm:g} cm)"
    )


def _measure_apart(goal: ApartGoal, positions: Array, characters: Sequence[Character]) -> Measured:
    """The smallest distance (cm) between the two points over the range, where it occurs, and
    the frames closer than the minimum."""
    n = positions.shape[0]
    end = n if goal.end is None else min(goal.end, n)
    start = min(goal.start, end)
    d = point_distance(goal.a, goal.b, positions[start:end], characters)
    if d.size == 0:
        e: dict[str, Any] = {"start": goal.start, "end": goal.end, "missing": True, "satisfied": False}
        return e, f"{goal.name}: frames {goal.start}-{goal.end} are beyond the motion's {n} frames"
    k = int(np.argmin(d))
    low = goal.min_m - goal.tolerance_cm / 100
    close = int(np.count_nonzero(d < low - 1e-9))
    ok = close == 0
    e = {
        "a": goal.a.label,
        "b": goal.b.label,
        "start": start,
        "end": end,
        "min_distance_cm": _r(100 * float(d[k])),
        "frame": start + k,
        "min_cm": _r(100 * goal.min_m),
        "frames": close,
        "tolerance_cm": goal.tolerance_cm,
        "satisfied": ok,
    }
    return e, None if ok else (
        f"{goal.name}: {goal.a.label} and {goal.b.label} come {100 * float(d[k]):.1f} cm close at frame "
        f"{start + k} ({close} frames under {100 * goal.min_m:g} cm)"
    )


def hold_figures(d: Array, max_m: float) -> dict[str, float]:
    """Figures of a hold's per-frame distances ``d (F,)`` metres: the fraction of frames within
    ``max_m``, the median, 90th percentile and largest distance (cm)."""
    return {
        "held_fraction": _r(float(np.mean(d <= max_m + 1e-9))),
        "median_cm": _r(100 * float(np.median(d))),
        "p90_cm": _r(100 * float(np.percentile(d, 90))),
        "max_cm": _r(100 * float(d.max())),
    }


def _measure_hold(goal: HoldGoal, positions: Array, characters: Sequence[Character]) -> Measured:
    """How much of the output the two points spend within the hold distance."""
    d = point_distance(goal.a, goal.b, positions, characters)
    fig = hold_figures(d, goal.max_m)
    ok = fig["held_fraction"] >= goal.min_fraction
    e: dict[str, Any] = {
        "a": goal.a.label,
        "b": goal.b.label,
        **fig,
        "frame": int(np.argmax(d)),
        "tolerance_cm": _r(100 * goal.max_m),
        "tolerance": goal.min_fraction,
        **dict(goal.extra),
        "satisfied": ok,
    }
    return e, None if ok else (
        f"{goal.name}: {goal.a.label} and {goal.b.label} are within {100 * goal.max_m:g} cm in "
        f"{100 * fig['held_fraction']:.0f}% of the frames (at least {100 * goal.min_fraction:.0f}% asked; "
        f"median {fig['median_cm']:.1f} cm)"
    )
