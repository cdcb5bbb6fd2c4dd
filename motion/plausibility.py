"""Physical plausibility of a motion against the examples it was made from.

A synthesized motion is plausible when it moves no faster, turns no faster, slides its planted
feet no more, sinks into the floor no deeper and jerks no harder than the database's own
examples. :func:`profile` measures one character's motion; :func:`reference_from_profiles`
pools the profiles of the examples into a :class:`Reference`; :func:`plausibility_checks`
compares an output's profile with it.

Every figure is measured on joint positions in metres (Y up) with the same code for the
examples and the output:

* **root speed** — the body root's floor speed (the hips' projection, :func:`motion.ground.body_root`),
  over a window of :data:`SPEED_WINDOW_S` so capture noise does not count; peak and 99th percentile.
* **turn rate** — the heading's rate of change (:func:`motion.ground.facing_from_positions`) over
  the same window, degrees per second.
* **planted-foot slide** — per frame, the floor speed of the *lowest* foot joint (the foot in
  contact by height, whatever its speed: a dragged body scores its drag), median over frames.
* **foot speed** — the fastest foot joint (ankle or toe), frame to frame, against the examples'
  fastest: a foot that snaps (a clean-up or a blend moving it in one frame) moves faster than any
  foot of the examples (reported with its ratio, not gated: :data:`FOOT_SPEED_MARGIN`).
* **floor penetration** — how far the lowest foot joint (any joint for skeletons without feet)
  goes below the examples' floor level.
* **joint step** — the largest frame-to-frame displacement of any joint (a teleport).
* **join spikes** — the largest joint acceleration within two frames of a cut or join, at
  :data:`ACCEL_RATE_HZ` whatever the frame rate (so noise at 120 fps counts like at 30 fps).
* **jerk** — mean magnitude of the third derivative of joint positions (reported, not gated).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt

from .contacts import foot_joints
from .errors import MotionError
from .ground import body_root, facing_from_positions
from .metrics import points_jerk
from .skeleton import Skeleton
from .units import standing_height
from .vectors import norms

Array = npt.NDArray[np.float64]

REFERENCE_VERSION = 2
"""Version of the figures a stored :class:`Reference` holds; a database built with another one
is measured again when loaded."""
SPEED_WINDOW_S = 1.0 / 6.0
"""Seconds over which root speed and turn rate are measured (5 frames at 30 fps)."""
ACCEL_RATE_HZ = 30.0
"""Accelerations are second differences over steps of ``round(fps / ACCEL_RATE_HZ)`` frames."""
JOIN_HALF_WIDTH_S = 2.0 / 30.0
"""Join spikes are looked for this far either side of each join."""

SPEED_MARGIN = 1.10
"""Peak root speed may exceed the fastest example by this factor."""
SPEED_P99_MARGIN = 1.25
"""The root speed's 99th percentile may exceed the examples' by this factor (bursts at joins)."""
TURN_MARGIN = 1.10
"""Peak turn rate may exceed the fastest-turning example by this factor."""
SLIDE_MARGIN, SLIDE_FLOOR_M_S = 1.25, 0.02
"""Planted-foot slide may reach ``SLIDE_MARGIN x`` the worst example's ``+ SLIDE_FLOOR_M_S``."""
STEP_MARGIN, STEP_FLOOR_M = 1.5, 0.02
"""A joint may move ``STEP_MARGIN x`` the fastest example joint's per-frame step ``+ STEP_FLOOR_M``."""
JOIN_MARGIN = 2.0
"""Joint acceleration at joins may reach this factor of the examples' 99.9th percentile (a toe
pushing off at a cut reaches 1.5 times it without a visible pop; a pop is 3-5 times it)."""
FOOT_SPEED_MARGIN = 1.3
"""A foot faster than this factor of the examples' fastest foot (frame to frame) snaps: the
report's ``foot_speed`` gives it as ``snap_limit`` (reported, not gated: engine results still
reach it at some movement joins, e.g. 1.45 on the rhythm example of docs/rhythm.md at 90 BPM)."""
FLOOR_MARGIN_M = 0.02
"""The lowest joint may sink this much deeper below the floor than the examples ever do."""


@dataclass(frozen=True, slots=True)
class Profile:
    """Per-frame measures of one character (see the module docstring), all metres and seconds.

    ``root_speed (F - w,)`` m/s, ``turn_rate (F - w,)`` rad/s (empty without left/right joints),
    ``joint_speed (F - 1,)`` fastest joint per frame m/s and ``step_joint (F - 1,)`` which joint,
    ``accel (F,)`` largest joint acceleration m/s^2 (NaN where undefined), ``foot_speed (F - 1,)``
    lowest foot m/s and ``fastest_foot (F - 1,)`` fastest foot m/s (empty without feet),
    ``lowest (F,)`` lowest foot joint's height m (any
    joint's without feet: a static reference joint such as Bandai-Namco's ``joint_Root`` on the
    floor would otherwise hide every foot that sinks), ``jerk`` m/s^3,
    ``height`` m (standing), ``fps``.
    """

    fps: float
    height: float
    root_speed: Array
    turn_rate: Array
    joint_speed: Array
    step_joint: npt.NDArray[np.intp]
    accel: Array
    foot_speed: Array
    fastest_foot: Array
    lowest: Array
    jerk: float


def _window(fps: float, seconds: float) -> int:
    return max(1, int(round(seconds * fps)))


def profile(positions: Array, skeleton: Skeleton, fps: float) -> Profile:
    """The :class:`Profile` of one character: ``positions (F, J, 3)`` metres, Y up, of the joints
    of ``skeleton`` (in its order), sampled at ``fps``."""
    pos = np.asarray(positions, dtype=np.float64)
    n = pos.shape[0]
    if pos.ndim != 3 or pos.shape[1] != skeleton.num_joints:
        raise MotionError(f"positions {pos.shape} do not match a {skeleton.num_joints}-joint skeleton")
    w = _window(fps, SPEED_WINDOW_S)
    xz = pos[:, body_root(skeleton)][:, [0, 2]]
    root_speed = norms(xz[w:] - xz[:-w]) * fps / w if n > w else np.zeros(0)
    yaw = facing_from_positions(skeleton, pos) if n > w else None
    turn = np.abs(yaw[w:] - yaw[:-w]) * fps / w if yaw is not None else np.zeros(0)
    if n > 1:
        steps = norms(np.diff(pos, axis=0))  # (F-1, J)
        step_joint = np.argmax(steps, axis=1).astype(np.intp)
        joint_speed = steps[np.arange(n - 1), step_joint] * fps
    else:
        step_joint, joint_speed = np.zeros(0, np.intp), np.zeros(0)
    h = _window(fps, 1.0 / ACCEL_RATE_HZ)
    accel = np.full(n, np.nan)
    if n > 2 * h:
        a = pos[2 * h :] - 2.0 * pos[h:-h] + pos[: -2 * h]
        accel[h:-h] = norms(a).max(axis=1) * (fps / h) ** 2
    try:
        feet = foot_joints(skeleton)
    except MotionError:
        feet = np.zeros(0, dtype=np.intp)
    if feet.size and n > 1:
        low = np.argmin(pos[1:, feet, 1], axis=1)
        fxz = pos[:, feet][:, :, [0, 2]]
        speed = norms(np.diff(fxz, axis=0)) * fps  # (F-1, K)
        foot_speed = speed[np.arange(n - 1), low]
        fastest_foot = norms(np.diff(pos[:, feet], axis=0)).max(axis=1) * fps
    else:
        foot_speed = fastest_foot = np.zeros(0)
    return Profile(
        fps=float(fps),
        height=standing_height(pos),
        root_speed=root_speed,
        turn_rate=turn,
        joint_speed=joint_speed,
        step_joint=step_joint,
        accel=accel,
        foot_speed=foot_speed,
        fastest_foot=fastest_foot,
        lowest=(pos[:, feet, 1] if feet.size else pos[:, :, 1]).min(axis=1),
        jerk=points_jerk(pos, fps),
    )


@dataclass(frozen=True, slots=True)
class Reference:
    """What the examples of a database do (see the module docstring): speeds m/s, turn rates
    rad/s, accelerations m/s^2, lengths metres, jerk m/s^3. ``planted_slide`` is the largest
    per-clip median planted-foot slide; ``floor_y`` the median per-clip floor (5th percentile of
    the lowest joint); ``floor_depth`` how far below it any example's lowest joint ever goes."""

    clips: int
    height: float
    root_speed_max: float
    root_speed_p99: float
    turn_rate_max: float
    joint_speed_max: float
    accel_p999: float
    planted_slide: float
    foot_speed_max: float
    floor_y: float
    floor_depth: float
    jerk: float

    PREFIX = "quality.reference."

    def to_arrays(self) -> dict[str, npt.NDArray[Any]]:
        """The reference as npz-ready arrays (keys under :attr:`PREFIX`, with the measure's
        :data:`REFERENCE_VERSION`)."""
        out = {self.PREFIX + k: np.array(v, dtype=np.float64) for k, v in asdict(self).items()}
        out[self.PREFIX + "version"] = np.array(REFERENCE_VERSION)
        return out

    @classmethod
    def from_arrays(cls, arrays: Any) -> Reference | None:
        """The reference stored by :meth:`to_arrays`, or ``None`` when the arrays hold none (or
        one measured by another version of these figures: measure it again)."""
        keys = [f.name for f in fields(cls)]
        if any(cls.PREFIX + k not in arrays for k in keys):
            return None
        version = arrays.get(cls.PREFIX + "version") if hasattr(arrays, "get") else None
        if version is None or int(np.asarray(version)) != REFERENCE_VERSION:
            return None
        values = {k: float(np.asarray(arrays[cls.PREFIX + k])) for k in keys}
        values["clips"] = int(values["clips"])
        return cls(**values)  # type: ignore[arg-type]

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}


def _max(x: Array) -> float:
    return float(x.max()) if x.size else 0.0


def reference_from_profiles(profiles: Sequence[Profile]) -> Reference:
    """Pool the :class:`Profile` of every example clip into a :class:`Reference`."""
    if not profiles:
        raise MotionError("a quality reference needs at least one example")
    speeds = np.concatenate([p.root_speed for p in profiles])
    accel = np.concatenate([p.accel[np.isfinite(p.accel)] for p in profiles])
    slides = [float(np.median(p.foot_speed)) for p in profiles if p.foot_speed.size]
    floors = np.array([float(np.percentile(p.lowest, 5)) for p in profiles])
    floor_y = float(np.median(floors))
    lowest = min(float(p.lowest.min()) for p in profiles)
    frames = np.array([p.lowest.size for p in profiles], dtype=np.float64)
    return Reference(
        clips=len(profiles),
        height=float(np.median([p.height for p in profiles])),
        root_speed_max=_max(speeds),
        root_speed_p99=float(np.percentile(speeds, 99)) if speeds.size else 0.0,
        turn_rate_max=max(_max(p.turn_rate) for p in profiles),
        joint_speed_max=max(_max(p.joint_speed) for p in profiles),
        accel_p999=float(np.percentile(accel, 99.9)) if accel.size else 0.0,
        planted_slide=max(slides) if slides else 0.0,
        foot_speed_max=max(_max(p.fastest_foot) for p in profiles),
        floor_y=floor_y,
        floor_depth=max(floor_y - lowest, 0.0),
        jerk=float(np.average([p.jerk for p in profiles], weights=frames)),
    )


def reference_from_positions(examples: Sequence[tuple[Array, Skeleton, float]]) -> Reference:
    """:func:`reference_from_profiles` of ``(positions (F, J, 3) metres, skeleton, fps)`` examples."""
    return reference_from_profiles([profile(p, sk, fps) for p, sk, fps in examples])


def _check(
    value: float, limit: float | None, unit: str, reference: float | None, **extra: Any
) -> dict[str, Any]:
    out: dict[str, Any] = {
        "value": round(float(value), 4),
        "unit": unit,
        "reference": None if reference is None else round(float(reference), 4),
        "limit": None if limit is None else round(float(limit), 4),
        "ok": True if limit is None else bool(value <= limit + 1e-9),
    }
    out.update(extra)
    return out


def plausibility_checks(
    profiles: Sequence[Profile],
    reference: Reference | None,
    joins: npt.NDArray[np.intp] | None = None,
    joint_names: Sequence[Sequence[str]] | None = None,
) -> dict[str, dict[str, Any]]:
    """Each plausibility figure of an output (the worst over its characters) against the
    reference: ``{name: {"value", "unit", "reference", "limit", "ok", "character", ...}}``.

    ``joins`` are output frames where pieces of motion meet (cuts, movement joins); without a
    reference every figure is reported with ``limit`` None (not gated)."""
    if not profiles:
        return {}
    fps = profiles[0].fps
    out: dict[str, dict[str, Any]] = {}
    out.update(_speed_checks(profiles, reference, fps))
    out.update(_turn_check(profiles, reference))
    out.update(_slide_check(profiles, reference))
    out.update(_foot_speed_check(profiles, reference))
    out.update(_floor_check(profiles, reference))
    out["joint_step"] = _step_check(profiles, reference, fps, joint_names)
    if joins is not None and joins.size:
        out["join_spikes"] = _join_check(profiles, reference, fps, joins)
    v, c = _worst([p.jerk for p in profiles])
    out["jerk"] = _check(v, None, "m/s^3", None if reference is None else reference.jerk, character=c)
    return out


def _worst(values: list[float]) -> tuple[float, int]:
    """The largest value and its character (0.0 and 0 for none)."""
    i = int(np.argmax(values)) if values else 0
    return (float(values[i]) if values else 0.0), i


def _speed_checks(
    profiles: Sequence[Profile], ref: Reference | None, fps: float
) -> dict[str, dict[str, Any]]:
    """Peak and 99th-percentile root speed (m/s) against the fastest example."""
    w = _window(fps, SPEED_WINDOW_S)
    peak = [_max(p.root_speed) for p in profiles]
    v, c = _worst(peak)
    frame = int(np.argmax(profiles[c].root_speed)) + w // 2 if profiles[c].root_speed.size else 0
    out = {
        "root_speed": _check(
            v,
            None if ref is None else SPEED_MARGIN * ref.root_speed_max,
            "m/s",
            None if ref is None else ref.root_speed_max,
            ratio=None if ref is None or ref.root_speed_max <= 0 else round(v / ref.root_speed_max, 3),
            character=c,
            frame=frame,
        )
    }
    p99 = [float(np.percentile(p.root_speed, 99)) if p.root_speed.size else 0.0 for p in profiles]
    v, c = _worst(p99)
    out["root_speed_p99"] = _check(
        v,
        None if ref is None else SPEED_P99_MARGIN * ref.root_speed_p99,
        "m/s",
        None if ref is None else ref.root_speed_p99,
        character=c,
    )
    return out


def _turn_check(profiles: Sequence[Profile], ref: Reference | None) -> dict[str, dict[str, Any]]:
    """Peak turn rate (deg/s) against the examples' (none without a heading)."""
    if not any(p.turn_rate.size for p in profiles):
        return {}
    v, c = _worst([_max(p.turn_rate) for p in profiles])
    return {
        "turn_rate": _check(
            float(np.degrees(v)),
            None if ref is None else float(np.degrees(TURN_MARGIN * ref.turn_rate_max)),
            "deg/s",
            None if ref is None else float(np.degrees(ref.turn_rate_max)),
            character=c,
        )
    }


def _slide_check(profiles: Sequence[Profile], ref: Reference | None) -> dict[str, dict[str, Any]]:
    """Median planted-foot speed (m/s) against the examples' (none without feet)."""
    if not any(p.foot_speed.size for p in profiles):
        return {}
    v, c = _worst([float(np.median(p.foot_speed)) if p.foot_speed.size else 0.0 for p in profiles])
    return {
        "foot_slide": _check(
            v,
            None if ref is None else SLIDE_MARGIN * ref.planted_slide + SLIDE_FLOOR_M_S,
            "m/s",
            None if ref is None else ref.planted_slide,
            character=c,
        )
    }


def _foot_speed_check(profiles: Sequence[Profile], ref: Reference | None) -> dict[str, dict[str, Any]]:
    """The fastest foot (m/s, frame to frame) against the examples' fastest (none without feet)."""
    if not any(p.fastest_foot.size for p in profiles):
        return {}
    v, c = _worst([_max(p.fastest_foot) for p in profiles])
    pc = profiles[c]
    frame = int(np.argmax(pc.fastest_foot)) + 1 if pc.fastest_foot.size else 0
    known = ref is not None and ref.foot_speed_max > 0
    return {
        "foot_speed": _check(
            v,
            None,
            "m/s",
            ref.foot_speed_max if ref is not None else None,
            ratio=round(v / ref.foot_speed_max, 3) if ref is not None and known else None,
            snap_limit=round(FOOT_SPEED_MARGIN * ref.foot_speed_max, 4)
            if ref is not None and known
            else None,
            character=c,
            frame=frame,
        )
    }


def _floor_check(profiles: Sequence[Profile], ref: Reference | None) -> dict[str, dict[str, Any]]:
    """How far (cm) the lowest joint goes below the examples' floor, and for how many frames
    (needs a reference)."""
    if ref is None:
        return {}
    v, c = _worst([max(ref.floor_y - float(p.lowest.min()), 0.0) for p in profiles])
    below = int(np.count_nonzero(profiles[c].lowest < ref.floor_y - ref.floor_depth - FLOOR_MARGIN_M))
    return {
        "floor_penetration": _check(
            100.0 * v,
            100.0 * (ref.floor_depth + FLOOR_MARGIN_M),
            "cm",
            100.0 * ref.floor_depth,
            character=c,
            frames=below,
        )
    }


def _step_check(
    profiles: Sequence[Profile],
    ref: Reference | None,
    fps: float,
    joint_names: Sequence[Sequence[str]] | None,
) -> dict[str, Any]:
    """The largest per-frame jump (m) of any joint, with its frame and joint."""
    v, c = _worst([_max(p.joint_speed) / p.fps for p in profiles])
    pc = profiles[c]
    f = int(np.argmax(pc.joint_speed)) if pc.joint_speed.size else 0
    joint = int(pc.step_joint[f]) if pc.step_joint.size else 0
    names = joint_names[c] if joint_names is not None else None
    return _check(
        v,
        None if ref is None else STEP_MARGIN * ref.joint_speed_max / fps + STEP_FLOOR_M,
        "m",
        None if ref is None else ref.joint_speed_max / fps,
        character=c,
        frame=f + 1,
        joint=names[joint] if names is not None else joint,
    )


def _join_check(
    profiles: Sequence[Profile], ref: Reference | None, fps: float, joins: npt.NDArray[np.intp]
) -> dict[str, Any]:
    """The largest joint acceleration (m/s^2) near the frames where pieces of motion meet."""
    half = _window(fps, JOIN_HALF_WIDTH_S)
    spikes: list[float] = []
    where: list[int] = []
    for p in profiles:
        n = p.accel.size
        idx = (np.asarray(joins, dtype=np.intp)[:, None] + np.arange(-half, half + 1)[None, :]).ravel()
        idx = idx[(idx >= 0) & (idx < n)]
        a = p.accel[idx]
        ok = np.isfinite(a)
        if ok.any():
            k = int(np.argmax(np.where(ok, a, -np.inf)))
            spikes.append(float(a[k]))
            where.append(int(idx[k]))
        else:
            spikes.append(0.0)
            where.append(0)
    v, c = _worst(spikes)
    return _check(
        v,
        None if ref is None else JOIN_MARGIN * ref.accel_p999,
        "m/s^2",
        None if ref is None else ref.accel_p999,
        character=c,
        frame=where[c],
        joins=int(joins.size),
    )
