"""The quality report of a synthesized motion, measured on the motion itself.

:func:`assess` is the one function every engine's result goes through (the job runtime calls it on
the final motion: after warping, smoothing, blending, foot cleanup and any floor correction; the
exports only change its coordinate convention). It measures

* every goal the request set (:mod:`motion.goals`: length, body, joint, pose, obstacle, label,
  path, music beats, and between characters meet, apart and hold), each with ``satisfied``
  against a stated tolerance;
* physical plausibility against the database's own examples (:mod:`motion.plausibility`: root
  speed and turn rate, planted-foot slide, floor penetration, teleporting joints, spikes at joins,
  jerk);

and sums them up in one flag, ``ok``, with the ``reasons`` it is false, so a client can reject a
result with one check. Multi-character outputs (crowds, couples) are measured per character and
report the worst.

Example
-------
>>> from motion.goals import BodyGoal, LengthGoal
>>> report = assess(motion, QualityInputs(goals=(LengthGoal(300), BodyGoal("body[1]", 299,
...     np.array([3.0, 5.0]), np.radians(-90.0)))), reference)  # doctest: +SKIP
>>> report.ok, report.reasons  # doctest: +SKIP
(False, ['body[1] (frame 299): 12.3 cm from its goal (tolerance 5 cm / 5 deg)'])
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from .goals import Character, Goal, measure
from .motion import Motion
from .plausibility import Profile, Reference, plausibility_checks, profile

Array = npt.NDArray[np.float64]

_CHECK_NAMES = {
    "root_speed": "the body's peak speed",
    "root_speed_p99": "the body's speed (99th percentile)",
    "turn_rate": "the peak turn rate",
    "foot_slide": "the planted foot's slide",
    "foot_speed": "the fastest foot",
    "floor_penetration": "floor penetration",
    "joint_step": "the largest one-frame joint step",
    "join_spikes": "joint acceleration at joins",
}


@dataclass(frozen=True, slots=True)
class QualityInputs:
    """What :func:`assess` needs besides the motion: the request's ``goals``, the output's
    ``characters`` (default: the whole skeleton is one character) and the output frames where
    pieces of motion were joined (``joins``; cut and blend frames)."""

    goals: tuple[Goal, ...] = ()
    characters: tuple[Character, ...] = ()
    joins: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, dtype=np.intp))


@dataclass(frozen=True, slots=True)
class QualityReport:
    """``ok`` (every goal satisfied and every plausibility figure within its limit) and the
    ``reasons`` it is not; ``constraint_errors`` per goal name; ``plausibility`` per figure
    (``value``, ``unit``, ``reference``, ``limit``, ``ok``...); ``metrics`` the headline
    figures as plain floats."""

    ok: bool
    reasons: list[str]
    constraint_errors: dict[str, Any]
    plausibility: dict[str, dict[str, Any]]
    metrics: dict[str, float]


def default_characters(motion: Motion) -> tuple[Character, ...]:
    """The whole skeleton as one character."""
    return (Character(np.arange(motion.num_joints, dtype=np.intp), motion.skeleton),)


def character_profiles(positions_m: Array, fps: float, characters: Sequence[Character]) -> list[Profile]:
    """:func:`motion.plausibility.profile` of each character of an output (positions in metres)."""
    every = np.arange(positions_m.shape[1])  # the whole skeleton needs no copy of its columns
    return [
        profile(positions_m if np.array_equal(c.joints, every) else positions_m[:, c.joints], c.skeleton, fps)
        for c in characters
    ]


def assess(
    motion: Motion,
    inputs: QualityInputs | None = None,
    reference: Reference | None = None,
    positions: Array | None = None,
) -> QualityReport:
    """The quality report of ``motion`` (module docstring).

    Parameters
    ----------
    motion:
        The returned motion (any units; measured in metres).
    inputs:
        The request's goals, the characters and the joins (:class:`QualityInputs`).
    reference:
        What the database's examples do (:class:`motion.plausibility.Reference`); without one the
        plausibility figures are reported but not gated.
    positions:
        ``motion.global_positions()`` when the caller has them (file units).
    """
    inputs = inputs or QualityInputs()
    pos = motion.global_positions() if positions is None else positions
    pos_m = np.asarray(pos, dtype=np.float64)
    if motion.metres_per_unit != 1.0:
        pos_m = pos_m * motion.metres_per_unit
    characters = inputs.characters or default_characters(motion)
    reasons: list[str] = []
    errors: dict[str, Any] = {}
    reach = reference.root_speed_max if reference is not None else None
    for goal in inputs.goals:
        entry, why = measure(goal, pos_m, motion.fps, characters, reach)
        errors[goal.name] = entry
        if why is not None:
            reasons.append(why)
    profiles = character_profiles(pos_m, motion.fps, characters)
    names = [[motion.skeleton.names[int(j)] for j in c.joints] for c in characters]
    checks = plausibility_checks(profiles, reference, inputs.joins, names)
    for key, check in checks.items():
        if not check["ok"]:
            who = f" (character {check['character']})" if len(characters) > 1 else ""
            where = f" at frame {check['frame']}" if "frame" in check else ""
            extra = f", joint {check['joint']}" if key == "joint_step" else ""
            reasons.append(
                f"{_CHECK_NAMES.get(key, key)}{who} is {check['value']:g} {check['unit']}{where}{extra}, "
                f"above the limit {check['limit']:g} {check['unit']} "
                f"(the examples reach {check['reference']:g})"
            )
    metrics = _headline(checks, errors)
    return QualityReport(not reasons, reasons, errors, checks, metrics)


def _headline(checks: dict[str, dict[str, Any]], errors: dict[str, Any]) -> dict[str, float]:
    """The report's flat ``metrics``: one float per figure."""
    out: dict[str, float] = {}
    units = {"m/s": "m_s", "deg/s": "deg_s", "cm": "cm", "m": "m", "m/s^2": "m_s2", "m/s^3": "m_s3"}
    names = {
        "root_speed": "root_speed_max",
        "root_speed_p99": "root_speed_p99",
        "turn_rate": "turn_rate_max",
        "foot_slide": "foot_slide",
        "foot_speed": "foot_speed_max",
        "floor_penetration": "floor_penetration",
        "joint_step": "joint_step_max",
        "join_spikes": "join_accel_max",
        "jerk": "jerk",
    }
    for key, check in checks.items():
        out[f"{names.get(key, key)}_{units.get(check['unit'], 'x')}"] = float(check["value"])
    if checks.get("root_speed", {}).get("ratio") is not None:
        out["root_speed_ratio"] = float(checks["root_speed"]["ratio"])
    if checks.get("foot_speed", {}).get("ratio") is not None:
        out["foot_speed_ratio"] = float(checks["foot_speed"]["ratio"])
    meets = [float(e["error_cm"]) for e in errors.values() if isinstance(e, dict) and "wanted_cm" in e]
    aparts = [float(e["min_distance_cm"]) for e in errors.values() if isinstance(e, dict) and "min_cm" in e]
    if meets:
        out["shared_meet_error_cm_max"] = max(meets)
    if aparts:
        out["shared_min_distance_cm"] = min(aparts)
    for entry in errors.values():
        if isinstance(entry, dict) and "beat_align_mint" in entry:
            out["beat_align_mint"] = float(entry["beat_align_mint"])
            out["beat_align_bailando"] = float(entry["beat_align_bailando"])
    return out
