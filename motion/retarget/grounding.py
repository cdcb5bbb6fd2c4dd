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

In ``"lock"`` mode the planted feet are then held in place by
:func:`motion.footskate.solve_foot_skate` (the quality report's contacts of the ankle and toe
joints, detected on the transferred motion; each pinned where it stands over its run, so that a
flat foot's toe lands where it stood), and the passes run again without the pitch (which would
move a held toe) to put the soles back on the floor: they move the feet up or down only, so the
held places on the floor's plane stay. ``"grounding"`` does the three passes only (planted
feet keep the source's path over the floor); ``"free"`` leaves the motion as it is.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..contacts import bool_runs, detect_contacts, foot_plants
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
FOOT_PITCH_MAX_DEG = 30.0
"""A planted foot pitches about its ankle at most this far to reach the floor."""
PLANT_ROUNDS = 3
"""The passes run again (at most this many times in all) when a plant found on their result lasts
longer than they held it (a foot brought onto the floor becomes planted a little earlier): the
plants a result's contact events show are those whose soles were put on the floor."""
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


def _extensions(found: npt.NDArray[np.bool_], held: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """``(F, S)`` the runs of ``found`` that overlap a run of ``held`` (a plant found longer on
    the result than it was held), not plants found anew (a foot hovering where the source plants
    none stays off the floor)."""
    out = np.zeros_like(found)
    for k in range(found.shape[1]):
        for a, b in bool_runs(found[:, k]):
            if held[a:b, k].any():
                out[a:b, k] = True
    return out


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


def _circle(points: Array, pivot: Array, axis: Array) -> tuple[Array, Array]:
    """How the heights of ``points (F, P, 3)`` change as they turn about ``pivot (F, 3)`` by an
    angle ``t`` about the horizontal unit ``axis (F, 3)``: ``y(t) = pivot_y + radius cos(t - phase)``;
    returns ``radius (F, P)`` and ``phase (F, P)``."""
    rel = points - pivot[:, None]
    along = np.sum(rel * axis[:, None], axis=-1, keepdims=True)
    perp = rel - along * axis[:, None]
    a = perp[:, :, 1]
    b = np.cross(np.broadcast_to(axis[:, None], perp.shape), perp)[:, :, 1]
    return np.hypot(a, b), np.arctan2(b, a)


def lift_angles(points: Array, pivot: Array, axis: Array, floor: float) -> Array:
    """``(F,)`` the smallest angle ``t >= 0`` turning ``points (F, P, 3)`` about ``pivot (F, 3)``
    and the horizontal ``axis (F, 3)`` that leaves none of them under ``floor`` (points it cannot
    raise are left out; where the floor is out of a point's reach, the angle that raises it most)."""
    radius, phase = _circle(points, pivot, axis)
    c = (floor - pivot[:, 1])[:, None] / np.maximum(radius, 1e-300)
    need = np.where(c <= 1.0, phase - np.arccos(np.clip(c, -1.0, 1.0)), phase)
    below = radius * np.cos(phase) + pivot[:, 1, None] < floor
    helps = (phase > 0) & (radius > 1e-9)  # turning up raises it at first
    return np.asarray(np.where(below & helps, np.clip(need, 0.0, None), 0.0).max(axis=1))


def reach_angles(points: Array, pivot: Array, axis: Array, floor: float) -> Array:
    """``(F,)`` the smallest angle ``t >= 0`` turning ``points (F, P, 3)`` about ``pivot (F, 3)``
    and the horizontal ``axis (F, 3)`` that brings one of them down onto ``floor`` (0 where one is
    already at or under it; ``inf`` where none can reach it)."""
    radius, phase = _circle(points, pivot, axis)
    c = (floor - pivot[:, 1])[:, None] / np.maximum(radius, 1e-300)
    start = np.mod(phase + np.arccos(np.clip(c, -1.0, 1.0)), 2.0 * np.pi)
    need = np.where(c >= 1.0, 0.0, np.where(c < -1.0, np.inf, start))
    need = np.where(radius * np.cos(phase) + pivot[:, 1, None] <= floor, 0.0, need)
    return np.asarray(need.min(axis=1))


def _with_turns(motion: Motion, grot: Array, turns: dict[int, Array]) -> Motion:
    """``motion`` with joints ``turns`` keys turned in the world by the ``(F, 4)`` rotations
    (``grot (F, J, 4)``: the motion's global rotations); their children follow."""
    local = np.array(motion.rotations, copy=True)
    parents = motion.skeleton.parents
    for j, q in turns.items():
        g_new = rot.multiply(q, grot[:, j])
        p = int(parents[j])
        local[:, j] = g_new if p < 0 else rot.multiply(rot.inverse(grot[:, p]), g_new)
    return Motion(
        motion.skeleton,
        motion.root_positions,
        rot.normalize(local),
        motion.fps,
        motion.joint_translations,
        motion.units,
        motion.name,
    )


def _pitch_feet(motion: Motion, soles: tuple[Sole, ...], floor: float, plants: Array, rate: float) -> Motion:
    """Pass 1b: a planted foot the leg could not bring down (a straight leg at push-off or at a
    heel strike) pitches about its ankle, toes down or heel down, whichever reaches the floor
    with less turn (at most :data:`FOOT_PITCH_MAX_DEG`), weighted by the plant and enveloped."""
    pos, grot = motion.fk()
    turns: dict[int, Array] = {}
    limit = np.radians(FOOT_PITCH_MAX_DEG)
    for k, sole in enumerate(soles):
        w = plants[:, k]
        if not w.any():
            continue
        pts = sole.positions(pos, grot)
        ankle = pos[:, sole.ankle]
        axis = sole.across_world(grot)  # up x forward: a positive turn lowers points ahead
        down = reach_angles(pts, ankle, axis, floor)
        back = reach_angles(pts, ankle, -axis, floor)
        signed = np.where(down <= back, np.minimum(down, limit), -np.minimum(back, limit))
        signed = np.where(np.isfinite(signed), signed, 0.0) * w
        reach = float(np.max(np.linalg.norm(sole.local[:, 0], axis=-1), initial=0.0))
        step = rate / max(reach, 1e-9)
        toe_down = upper_envelope(np.maximum(signed, 0.0), step)
        heel_down = upper_envelope(np.maximum(-signed, 0.0), step)
        angle = np.minimum(toe_down, limit) - np.minimum(heel_down, limit)
        if angle.any():
            turns[sole.ankle] = rot.from_axis_angle(axis, angle)
    return _with_turns(motion, grot, turns) if turns else motion


def _roll_toes(motion: Motion, soles: tuple[Sole, ...], floor: float, rate: float) -> Motion:
    """Pass 2: each toe bent up about its joint (the ball) by the smallest angle that keeps its
    sole points on or above ``floor``, at most :data:`TOE_ROLL_MAX_DEG`, enveloped in time."""
    pos, grot = motion.fk()
    turns: dict[int, Array] = {}
    limit = np.radians(TOE_ROLL_MAX_DEG)
    for sole in soles:
        if sole.toe < 0 or not sole.on_toe.any():
            continue
        pts = sole.positions(pos, grot)[:, sole.on_toe]  # (F, P, 3)
        ball = pos[:, sole.toe]
        axis = -sole.across_world(grot, toe=True)  # forward x up: a positive turn raises points ahead
        theta = np.minimum(lift_angles(pts, ball, axis, floor), limit)
        if not theta.any():
            continue
        reach = float(np.max(np.linalg.norm(sole.local[sole.on_toe, 0], axis=-1), initial=0.0))
        theta = np.minimum(upper_envelope(theta, rate / max(reach, 1e-9)), limit)
        turns[sole.toe] = rot.from_axis_angle(axis, theta)
    return _with_turns(motion, grot, turns) if turns else motion


def _residual(motion: Motion, soles: tuple[Sole, ...], floor: float, rate: float) -> Array:
    """``(F, S)`` pass 3's lift: the whole sole's deficit under the floor, enveloped."""
    pos, grot = motion.fk()
    out = np.zeros((motion.num_frames, len(soles)))
    for k, sole in enumerate(soles):
        deficit = np.maximum(floor - _lowest(sole, sole.around(pos, grot), None), 0.0)
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
    pins: tuple[npt.NDArray[np.intp], npt.NDArray[np.bool_]] | None = None
    if mode == "lock":  # the quality report's contacts, each joint on its own (a toe at push-off)
        joints = np.array(
            [j for s in soles for j in ((s.ankle, s.toe) if s.toe >= 0 else (s.ankle,))], dtype=np.intp
        )
        pins = detect_contacts(motion, joints, positions=pos)
    placed = motion
    for _ in range(PLANT_ROUNDS):
        plants = np.stack([plant_weights(flags[:, k], blend) for k in range(len(soles))], axis=1)
        motion = _on_floor(placed, soles, floor, plants, rate, pitch=True)
        if pins is not None:  # held in place as it now stands, then its height made right again
            held = solve_foot_skate(motion, pins, blend_s=blend_s).motion
            motion = _on_floor(held, soles, floor, plants, rate, pitch=False)
        found = _plant_flags(motion, soles, np.ascontiguousarray(motion.global_positions()))
        longer = _extensions(found, flags)
        if not (longer & ~flags).any():
            break
        flags |= longer  # a plant the result shows longer than the passes held it: hold it all
    return motion


def _on_floor(
    motion: Motion, soles: tuple[Sole, ...], floor: float, plants: Array, rate: float, *, pitch: bool
) -> Motion:
    """Passes 1 to 3 of the module docstring (the pitch of pass 1 only with ``pitch``)."""
    motion = _lift_feet(motion, soles, _heights(motion, soles, floor, plants, rate))
    if pitch:
        motion = _pitch_feet(motion, soles, floor, plants, rate)
    motion = _roll_toes(motion, soles, floor, rate)
    lift = _residual(motion, soles, floor, rate)
    return _lift_feet(motion, soles, lift) if lift.any() else motion
