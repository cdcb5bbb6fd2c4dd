"""The character's soles on its floor: planted soles touch it, no sole goes under it, smoothly.

After a rotation transfer the character's feet follow the source's, but its own soles
(:mod:`motion.retarget.sole`: heel, ball and toe tip, from its skinned mesh or its bones) do not
know the floor: a heel landing toe-up dips its corner under it, toes that the source has no joint
for keep their rest bend and plunge into it at push-off, and a foot the source plants may hover.
:func:`ground_feet` fixes that in three passes, each a smooth function of time:

1. **Height of each foot.** The foot's clearance ``c(t)`` is the lowest point of its sole (the
   heel part, moving with the foot bone, when the toes can bend on their own) above the floor.
   During a plant (:func:`motion.contacts.foot_plants` on the foot's ankle and toe: one plant
   whichever touches) the foot is moved by ``-c`` (down onto the floor, or up out of it); outside
   plants by ``max(-c, 0)`` (up, only where it would sink); the two blend over ``blend_s`` around
   each plant (smoothstep weights). The shift is then raised to its upper envelope of slope
   ``max_speed`` (the smallest function above it that changes no faster: a lift starts early
   enough instead of snapping), and applied by two-bone leg IK with the foot's orientation kept
   (:func:`motion.footskate.move_feet`), so the whole sole moves by it.
2. **Toes roll.** Where a toe point is still under the floor, the toe bends up about the ball by
   the smallest angle that brings it onto the floor (at most :data:`TOE_ROLL_MAX_DEG`), enveloped
   in time likewise: at push-off the toes stay on the floor while the heel rises, as a foot does.
3. **What is left** (a toe that cannot bend further, a character without toe bones) lifts the
   whole foot, enveloped likewise.

In ``"lock"`` mode the planted feet are first held in place on the floor's plane by
:func:`motion.footskate.solve_foot_skate` (contacts of the ankle and toe joints, horizontal pins
only: the height is the soles' business). ``"grounding"`` does the three passes only (planted
feet keep the source's path over the floor); ``"free"`` leaves the motion as it is.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..contacts import detect_contacts, foot_plants
from ..errors import MotionError
from ..footskate import move_feet, solve_foot_skate
from ..motion import Motion
from .sole import Sole

Array = npt.NDArray[np.float64]

FEET_MODES = ("lock", "grounding", "free")
"""What happens to the feet (``--feet``): held in place where planted and kept on the floor; kept
on the floor only; left as the transfer made them."""
TOE_ROLL_MAX_DEG = 70.0
"""The toes bend up at most this far to stay on the floor (a foot's toes reach 60-90 degrees)."""
BLEND_S = 0.1
"""Seconds over which a plant's pull onto the floor fades in and out."""


def smoothstep(x: Array) -> Array:
    x = np.clip(x, 0.0, 1.0)
    return np.asarray(x * x * (3.0 - 2.0 * x))


def plant_weights(flags: npt.NDArray[np.bool_], blend: int) -> Array:
    """``(F,)`` 1 on planted frames ``flags (F,)``, fading to 0 over ``blend`` frames either side
    (smoothstep of the distance to the nearest planted frame)."""
    n = flags.shape[0]
    if not flags.any():
        return np.zeros(n)
    idx = np.arange(n)
    last = np.maximum.accumulate(np.where(flags, idx, -(10**9)))
    nxt = np.minimum.accumulate(np.where(flags, idx, 10**9)[::-1])[::-1]
    dist = np.minimum(idx - last, nxt - idx).astype(np.float64)
    return smoothstep(1.0 - dist / (blend + 1.0))


def upper_envelope(values: Array, rate: float) -> Array:
    """``(F,)`` the smallest function at or above ``values (F,)`` that changes by at most ``rate``
    per frame: ``max over s of values[s] - rate |t - s|`` (two running maxima, O(F))."""
    if values.size == 0 or not np.isfinite(rate):
        return np.array(values, dtype=np.float64, copy=True)
    t = np.arange(values.size, dtype=np.float64) * rate
    ahead = np.maximum.accumulate(values + t) - t
    behind = (np.maximum.accumulate((values - t)[::-1]) + t[::-1])[::-1]
    return np.maximum(ahead, behind)


def _plant_flags(motion: Motion, soles: tuple[Sole, ...], pos: Array) -> npt.NDArray[np.bool_]:
    """``(F, S)`` the frames each sole's foot is planted (:func:`motion.contacts.foot_plants`)."""
    groups = [(s.ankle,) + ((s.toe,) if s.toe >= 0 else ()) for s in soles]
    flags = np.zeros((motion.num_frames, len(soles)), dtype=bool)
    for g, a, b in foot_plants(motion, groups, positions=pos):
        flags[a:b, g] = True
    return flags


def _lowest(sole: Sole, points: Array, part: npt.NDArray[np.bool_] | None) -> Array:
    """``(F,)`` height of the lowest of ``points (F, P, 3)`` (those in ``part`` when given)."""
    sel = points if part is None else points[:, part]
    return np.asarray(sel[:, :, 1].min(axis=1))


def _lift_feet(motion: Motion, soles: tuple[Sole, ...], shifts: Array) -> Motion:
    """``motion`` with each sole's ankle raised by ``shifts (F, S)`` (leg IK, foot orientation
    kept)."""
    moves = np.zeros((motion.num_frames, len(soles), 3))
    moves[:, :, 1] = shifts
    return move_feet(motion, np.array([s.ankle for s in soles], dtype=np.intp), moves)


def _heights(motion: Motion, soles: tuple[Sole, ...], floor: float, plants: Array, rate: float) -> Array:
    """``(F, S)`` pass 1's vertical shift of each foot (module docstring)."""
    pos, grot = motion.fk()
    out = np.zeros((motion.num_frames, len(soles)))
    for k, sole in enumerate(soles):
        heel_part = ~sole.on_toe if sole.toe >= 0 and sole.on_toe.any() and (~sole.on_toe).any() else None
        clearance = _lowest(sole, sole.positions(pos, grot), heel_part) - floor
        want = plants[:, k] * -clearance + (1.0 - plants[:, k]) * np.maximum(-clearance, 0.0)
        out[:, k] = upper_envelope(want, rate)
    return out


def _roll_toes(motion: Motion, soles: tuple[Sole, ...], floor: float, rate: float) -> Motion:
    """Pass 2: each toe bent up about its joint (the ball) by the smallest angle that keeps its
    sole points on or above ``floor``, at most :data:`TOE_ROLL_MAX_DEG`, enveloped in time."""
    pos, grot = motion.fk()
    local = np.array(motion.rotations, copy=True)
    parents = motion.skeleton.parents
    up = np.array([0.0, 1.0, 0.0])
    changed = False
    for sole in soles:
        if sole.toe < 0 or not sole.on_toe.any():
            continue
        pts = sole.positions(pos, grot)[:, sole.on_toe]  # (F, P, 3)
        ball = pos[:, sole.toe]
        rel = pts - ball[:, None]
        ahead = rel.mean(axis=1) * [1.0, 0.0, 1.0]
        ahead_n = np.linalg.norm(ahead, axis=-1, keepdims=True)
        if not np.all(ahead_n > 1e-12):
            ahead = np.where(ahead_n > 1e-12, ahead, rot.rotate(grot[:, sole.ankle], np.array([0.0, 0.0, 1.0])) * [1, 0, 1])
            ahead_n = np.linalg.norm(ahead, axis=-1, keepdims=True)
        fwd = ahead / np.maximum(ahead_n, 1e-300)
        axis = np.cross(fwd, up)  # turning about it by a positive angle lifts points ahead
        along = np.sum(rel * axis[:, None], axis=-1, keepdims=True)
        perp = rel - along * axis[:, None]
        a = perp[:, :, 1]
        b = np.cross(np.broadcast_to(axis[:, None], perp.shape), perp)[:, :, 1]
        radius = np.hypot(a, b)
        phi = np.arctan2(b, a)
        c = (floor - ball[:, 1])[:, None] / np.maximum(radius, 1e-300)
        need = np.where(c <= 1.0, phi - np.arccos(np.clip(c, -1.0, 1.0)), phi)
        helps = (phi > 0) & (radius > 1e-9)  # points behind the ball only go lower
        below = np.cos(phi) * radius + ball[:, None, 1] < floor  # ... at angle 0: under the floor
        need = np.where(helps & below, np.clip(need, 0.0, None), 0.0)
        theta = np.minimum(need.max(axis=1), np.radians(TOE_ROLL_MAX_DEG))
        if not theta.any():
            continue
        reach = float(np.max(np.linalg.norm(sole.local[sole.on_toe, 0], axis=-1), initial=0.0))
        theta = np.minimum(upper_envelope(theta, rate / max(reach, 1e-9)), np.radians(TOE_ROLL_MAX_DEG))
        turn = rot.from_axis_angle(axis, theta)
        g_new = rot.multiply(turn, grot[:, sole.toe])
        parent = int(parents[sole.toe])
        local[:, sole.toe] = rot.multiply(rot.inverse(grot[:, parent]), g_new)
        changed = True
    if not changed:
        return motion
    return Motion(
        motion.skeleton,
        motion.root_positions,
        rot.normalize(local),
        motion.fps,
        motion.joint_translations,
        motion.units,
        motion.name,
    )


def _residual(motion: Motion, soles: tuple[Sole, ...], floor: float, rate: float) -> Array:
    """``(F, S)`` pass 3's lift: the whole sole's deficit under the floor, enveloped."""
    pos, grot = motion.fk()
    out = np.zeros((motion.num_frames, len(soles)))
    for k, sole in enumerate(soles):
        deficit = np.maximum(floor - _lowest(sole, sole.positions(pos, grot), None), 0.0)
        out[:, k] = upper_envelope(deficit, rate) if deficit.any() else 0.0
    return out


def ground_feet(
    motion: Motion,
    soles: tuple[Sole, ...],
    floor: float,
    *,
    mode: str = "lock",
    blend_s: float = BLEND_S,
    max_speed: float | None = None,
) -> Motion:
    """``motion`` (a character in its own units) with its soles on ``floor`` (module docstring).

    Parameters
    ----------
    motion:
        The character moving, any units, Y up.
    soles:
        Its soles (:func:`motion.retarget.sole.mesh_soles` or :func:`~motion.retarget.sole.bone_soles`).
    floor:
        The floor's height (the rest pose's lowest sole point, :func:`motion.retarget.sole.soles_floor`).
    mode:
        One of :data:`FEET_MODES`.
    blend_s:
        Seconds over which a plant's pull onto the floor fades in and out.
    max_speed:
        How fast (motion units per second) a correction may change: the slope of the envelopes;
        default: the character's standing height per second.

    Raises
    ------
    MotionError
        For an unknown mode, or a foot without a hip-knee-ankle chain.
    """
    if mode not in FEET_MODES:
        raise MotionError(f"feet {mode!r}: use one of {', '.join(FEET_MODES)}")
    if mode == "free" or motion.num_frames < 2 or not soles:
        return motion
    blend = int(round(blend_s * motion.fps))
    pos = np.ascontiguousarray(motion.global_positions())
    if max_speed is None:
        from ..units import standing_height

        max_speed = standing_height(pos)
    rate = max_speed / motion.fps
    flags = _plant_flags(motion, soles, pos)
    if mode == "lock":
        joints = np.array([j for s in soles for j in ((s.ankle, s.toe) if s.toe >= 0 else (s.ankle,))], dtype=np.intp)
        joints, contacts = detect_contacts(motion, joints, positions=pos)
        motion = solve_foot_skate(motion, (joints, contacts), blend_s=blend_s, vertical=False).motion
    plants = np.stack([plant_weights(flags[:, k], blend) for k in range(len(soles))], axis=1)
    motion = _lift_feet(motion, soles, _heights(motion, soles, floor, plants, rate))
    motion = _roll_toes(motion, soles, floor, rate)
    lift = _residual(motion, soles, floor, rate)
    if lift.any():
        motion = _lift_feet(motion, soles, lift)
    return motion
