"""Foot-skate cleanup: keep planted feet planted with analytic two-bone leg IK.

For every contact run of a foot joint (ankle or toe) the joint is pinned to one world position:
the mean of its positions over the run (horizontal ``x, z`` and height ``y``, so the foot rests on
the floor height seen in that run). The correction ``target - position`` is faded in before a run
and out after it over ``blend_s`` seconds (smoothstep), and when two runs of a joint are closer
than twice that, the correction is interpolated across the gap, so nothing pops; a gap too short for
the foot to travel between two pinned places at :data:`PIN_TRAVEL_M_S` is first widened
(:func:`widen_jumps`: across a cut, two clips' planted feet may not line up).

Each leg is found by walking parents up from its foot joint: ankle -> knee -> hip, skipping
joints that sit at the same place as their child (zero-length bones). Per frame, vectorised over
frames, the leg is solved in closed form:

1. the knee rotates about the normal of the hip-knee-ankle plane (so it keeps bending in its
   original plane, towards its original pole) until the hip-ankle distance is the target's
   distance (law of cosines). A knee that is nearly straight (bent less than 10 degrees) or bent
   backwards has no such plane (it turns arbitrarily from frame to frame as the knee passes
   through straight): it bends about the leg's hinge axis, measured over the motion in the
   thigh's frame (:func:`hinge_axes`), with a smooth blend between the two (:func:`knee_axes`),
   so a target that bends a straight knee bends it forwards in every frame (bending it in the
   plane of a knee hyperextended by a fraction of a degree bent it backwards for a frame: a
   joint-acceleration spike of 200-400 m/s^2 in graph outputs near cuts). Beyond the leg's own
   extension in that frame, the distance is eased towards full extension ("soft IK":
   ``base + room * (1 - exp(-excess / room))``), so a target just out of reach bends the knee a
   little less instead of snapping it straight for a frame (a visible pop); the unreached part
   is left as residual;
2. the hip swings by the shortest arc that takes the ankle onto the target direction;
3. the ankle keeps its original global orientation (the foot does not rotate with the leg), and
   when a toe joint of that foot is pinned too, the foot turns by the shortest arc that brings
   the toe onto its own target. A toe pinned while its ankle is free (heel off) moves the whole
   foot by the toe's correction instead. With a floor, a toe that the solved leg still carries
   below it (its pin only fading in while the ankle's pin lowers the foot, or a foot whose length
   does not fit its two pinned targets) lifts the whole foot by what it lacks: the leg is solved
   again with both targets that much higher, so the foot keeps its orientation and its floor
   position (tilting the foot up instead swung a near-vertical toe sideways: larger joint
   accelerations at cuts); what the leg cannot reach is tilted up about the ankle
   (:func:`_lift_toe`).

Only local rotations of hips, knees and ankles change, so bone lengths are exactly preserved;
the root is untouched unless ``root_adjust`` is set, in which case the root is moved (smoothly,
at most ``max_root_shift_m``) by what the legs could not reach, and the legs are solved again.
Frames outside every run and blend window keep their exact original rotations.

Cost: one forward-kinematics pass plus ~30 quaternion/vector operations on the frames near
contacts; over 100k frames/s for a 20-joint skeleton on one core.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .contacts import detect_contacts
from .errors import MotionError
from .motion import Motion
from .skeleton import Skeleton
from .vectors import cross, norms

Array = npt.NDArray[np.float64]

_TOE = re.compile(r"toe", re.IGNORECASE)
_SAME_PLACE = 1e-6  # bones shorter than this fraction of the leg's longest offset are skipped
SOFT_IK_START = 0.97
"""Fraction of a leg's full reach beyond which a stretching target is eased (soft IK)."""
PIN_TRAVEL_M_S = 1.5
"""A foot moves between two pinned places no faster than this on average (``widen_jumps``)."""
KNEE_PLANE_SIN = float(np.sin(np.radians(10.0)))
"""A knee bent forward less than this (sine of its angle) bends partly about its hinge axis
rather than in its own plane (:func:`knee_axes`)."""
HINGE_MIN_SIN = 0.02
"""A knee whose bend averages less than this (sine) over the motion has no measurable hinge axis
(:func:`hinge_axes`): it bends towards the body's forward direction."""


@dataclass(frozen=True, slots=True)
class Leg:
    """Joint indices of one leg: ``hip`` rotates the thigh, ``knee`` the shin, ``ankle`` the foot;
    ``ankle_slot`` / ``toe_slot`` index the contact columns (``-1`` when that joint has none)."""

    hip: int
    knee: int
    ankle: int
    toe: int
    ankle_slot: int
    toe_slot: int


@dataclass(frozen=True)
class FootSkateResult:
    """Outcome of :func:`solve_foot_skate`.

    Attributes
    ----------
    motion:
        The cleaned motion.
    legs:
        The leg chains that were solved.
    residual:
        ``(F, K)`` distance (motion units) from each contact joint to its pinned target after the
        solve, over frames where the joint is in contact (0 elsewhere): what the leg could not reach.
    root_shift:
        ``(F, 3)`` translation added to the root (motion units; zeros unless ``root_adjust``).
    """

    motion: Motion
    legs: tuple[Leg, ...]
    residual: Array
    root_shift: Array


def _rest_positions(motion: Motion) -> Array:
    """``(J, 3)`` joint positions of the first frame (only distances along chains are used)."""
    return np.asarray(motion.slice(0, 1).global_positions()[0])


def _distinct_ancestor(skeleton: Skeleton, pos: Array, joint: int, scale: float) -> int:
    """Nearest ancestor of ``joint`` that is not at the same place (``-1`` when there is none)."""
    j = int(skeleton.parents[joint])
    while j >= 0 and np.linalg.norm(pos[j] - pos[joint]) <= _SAME_PLACE * scale:
        j = int(skeleton.parents[j])
    return j


def _is_ancestor(skeleton: Skeleton, a: int, b: int) -> bool:
    """True when joint ``a`` is a proper ancestor of joint ``b``."""
    j = int(skeleton.parents[b])
    while j >= 0:
        if j == a:
            return True
        j = int(skeleton.parents[j])
    return False


def leg_chains(motion: Motion, joints: npt.NDArray[np.intp], rest: Array | None = None) -> tuple[Leg, ...]:
    """Leg chains for contact joints ``joints (K,)``.

    A contact joint is a toe when its name contains ``toe`` or another contact joint is one of its
    ancestors; its ankle is that ancestor contact joint, else the nearest distinct ancestor. Other
    contact joints are ankles. From each ankle the knee and hip are the next distinct ancestors.
    Raises :class:`MotionError` when a foot has no hip-knee-ankle chain below the root, or when two
    legs share joints. ``rest``: ``(J, 3)`` joint positions of one frame, to tell zero-length bones
    (default: the first frame's).
    """
    sk = motion.skeleton
    pos = _rest_positions(motion) if rest is None else np.asarray(rest, dtype=np.float64)
    scale = float(np.abs(sk.offsets[1:]).max(initial=0.0)) or 1.0
    joint_list = [int(j) for j in joints]
    depth = sk.depth()
    for j in joint_list:
        if not 0 <= j < sk.num_joints:
            raise MotionError(f"contact joint {j} is not a joint of this {sk.num_joints}-joint skeleton")
    toe_of: dict[int, int] = {}  # ankle -> toe slot
    ankle_slot: dict[int, int] = {}
    for slot, j in enumerate(joint_list):
        above = [k for k in joint_list if k != j and _is_ancestor(sk, k, j)]
        if above or _TOE.search(sk.names[j]):
            ankle = (
                max(above, key=lambda k: int(depth[k])) if above else _distinct_ancestor(sk, pos, j, scale)
            )
            if ankle < 0:
                raise MotionError(f"toe joint {sk.names[j]!r} has no foot joint above it")
            if ankle in toe_of:
                raise MotionError(f"foot {sk.names[ankle]!r} has two toe contact joints; pass one per foot")
            toe_of[ankle] = slot
        else:
            ankle_slot[j] = slot
    legs: list[Leg] = []
    used: set[int] = set()
    for ankle in sorted(set(ankle_slot) | set(toe_of)):
        knee = _distinct_ancestor(sk, pos, ankle, scale)
        hip = _distinct_ancestor(sk, pos, knee, scale) if knee > 0 else -1
        if knee <= 0 or hip <= 0:
            raise MotionError(
                f"no leg chain (hip, knee, ankle below the root) above foot joint {sk.names[ankle]!r}"
            )
        toe_slot = toe_of.get(ankle, -1)
        toe = joint_list[toe_slot] if toe_slot >= 0 else -1
        chain = {hip, knee, ankle}
        if chain & used:
            raise MotionError(f"leg of {sk.names[ankle]!r} shares joints with another leg")
        used |= chain
        legs.append(Leg(hip, knee, ankle, toe, ankle_slot.get(ankle, -1), toe_slot))
    return tuple(legs)


def widen_jumps(
    positions: Array, flags: npt.NDArray[np.bool_], frames_per_metre: float, max_gap: int
) -> npt.NDArray[np.bool_]:
    """``(F,)`` contact flags of one joint whose gaps between runs leave the foot time to travel
    between the runs' pinned places at no more than ``1 / frames_per_metre`` metres per frame: a gap
    shorter than that (up to ``max_gap`` frames) is widened by taking frames from the ends of both
    runs (each keeps at least one frame); a gap of at most ``max_gap / 2`` frames between runs less
    than a frame's travel apart is a flicker of the contact, and is filled.

    The pin correction is interpolated across a gap; a foot pinned to two places 30 cm apart two
    frames apart (e.g. across a cut between two clips whose planted feet do not line up) would jump
    between them. ``positions (F, 3)`` are the joint's, in the units ``frames_per_metre`` uses."""
    col = np.array(flags, dtype=bool, copy=True)
    if max_gap <= 1 or not col.any():
        return col
    edges = np.diff(col.astype(np.int8), prepend=0, append=0)
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)  # ends exclusive
    if starts.size < 2:
        return col
    sums = np.add.reduceat(np.where(col[:, None], positions, 0.0), starts, axis=0)
    targets = sums / (ends - starts)[:, None]
    travels = norms(np.diff(targets, axis=0))
    for i in range(1, starts.size):
        travel = float(travels[i - 1])
        gap = int(starts[i] - ends[i - 1])
        if travel * frames_per_metre < 1.0 and gap <= max_gap // 2:
            col[ends[i - 1] : starts[i]] = True  # a flicker: the foot stays where it is
            continue
        need = min(int(np.ceil(travel * frames_per_metre)), max_gap)
        short = need - gap
        if short <= 0:
            continue
        take_a = min(short - short // 2, max(ends[i - 1] - starts[i - 1] - 1, 0))
        take_b = min(short - take_a, max(ends[i] - starts[i] - 1, 0))
        col[ends[i - 1] - take_a : ends[i - 1]] = False
        col[starts[i] : starts[i] + take_b] = False
        ends[i - 1] -= take_a
        starts[i] += take_b
    return col


def _smoothstep(x: Array) -> Array:
    x = np.clip(x, 0.0, 1.0)
    return np.asarray(x * x * (3.0 - 2.0 * x))


def pin_corrections(
    positions: Array, flags: npt.NDArray[np.bool_], blend: int, heights: Array | None = None
) -> tuple[Array, Array]:
    """Per-frame correction that pins one joint during each contact run, with faded edges.

    Parameters
    ----------
    positions:
        ``(F, 3)`` the joint's global positions.
    flags:
        ``(F,)`` contact flags.
    blend:
        Fade length in frames (0: no fade).
    heights:
        ``(F,)`` the height the joint should rest at in each frame (default: its own): a run is
        pinned at the mean of these over the run.

    Returns
    -------
    correction:
        ``(F, 3)`` ``target - position`` inside runs, the boundary correction faded over ``blend``
        frames outside them (interpolated across gaps shorter than ``2 * blend``), zero elsewhere.
    weight:
        ``(F,)`` in [0, 1]: 1 inside runs, the fade weights outside.
    """
    n = positions.shape[0]
    c = np.asarray(flags, dtype=bool)
    corr = np.zeros((n, 3))
    weight = np.zeros(n)
    if not c.any():
        return corr, weight
    edges = np.diff(c.astype(np.int8), prepend=0, append=0)
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)  # exclusive
    run_of = np.cumsum(edges[:-1] == 1) - 1
    rest = (
        positions
        if heights is None
        else np.concatenate((positions[:, :1], heights[:, None], positions[:, 2:]), axis=1)
    )
    sums = np.add.reduceat(np.where(c[:, None], rest, 0.0), starts, axis=0)
    targets = sums / (ends - starts)[:, None]
    corr[c] = targets[run_of[c]] - positions[c]
    weight[c] = 1.0
    gap = ~c
    if blend <= 0 or not gap.any():
        return corr, weight
    idx = np.arange(n)
    last = np.maximum.accumulate(np.where(c, idx, -1))  # last contact frame at or before f
    nxt = np.minimum.accumulate(np.where(c, idx, n)[::-1])[::-1]  # next contact frame at or after f
    f = idx[gap]
    e, s = last[gap], nxt[gap]
    has_e, has_s = e >= 0, s < n
    length = np.where(has_e & has_s, s - e - 1, n)  # gap length (n: open-ended)
    short = length < 2 * blend
    span = np.where(short, length + 1, blend + 1).astype(np.float64)
    w_out = np.where(has_e, _smoothstep(1.0 - (f - e) / span), 0.0)
    w_in = np.where(has_s, _smoothstep(1.0 - (s - f) / span), 0.0)
    corr[gap] = w_out[:, None] * corr[np.maximum(e, 0)] + w_in[:, None] * corr[np.minimum(s, n - 1)]
    # between runs the joint never goes below both its own height and the runs' rest heights (the
    # faded corrections of two runs at different heights would otherwise push it into the floor)
    rest_y = np.full(n, np.inf)
    rest_y[c] = targets[run_of[c], 1]
    below = np.minimum(
        np.where(has_e, rest_y[np.maximum(e, 0)], np.inf),
        np.where(has_s, rest_y[np.minimum(s, n - 1)], np.inf),
    )
    lowest = np.minimum(below, positions[gap, 1])
    corr[gap, 1] = np.maximum(corr[gap, 1], lowest - positions[gap, 1])
    weight[gap] = np.minimum(w_out + w_in, 1.0)
    return corr, weight


def _arc(a: Array, b: Array) -> Array:
    """Shortest-arc unit quaternions ``(N, 4)`` rotating directions ``a`` onto ``b`` (``(N, 3)``)."""
    na = norms(a)
    nb = norms(b)
    q = np.empty((a.shape[0], 4))
    q[:, :3] = cross(a, b)
    q[:, 3] = na * nb + np.einsum("ij,ij->i", a, b)
    norm = norms(q)
    bad = norm <= 1e-12 * np.maximum(na * nb, 1e-300)
    if bad.any():  # opposite (or zero) vectors: a half turn about any axis perpendicular to a
        perp = cross(a[bad], np.array([1.0, 0.0, 0.0]))
        weak = norms(perp) < 1e-6 * np.maximum(na[bad], 1e-300)
        perp[weak] = cross(a[bad][weak], np.array([0.0, 1.0, 0.0]))
        pn = norms(perp)[..., None]
        q[bad] = np.concatenate((perp / np.maximum(pn, 1e-300), np.zeros((perp.shape[0], 1))), axis=-1)
        q[bad & (na * nb == 0)] = rot.IDENTITY
        norm = norms(q)
    return np.asarray(q / norm[:, None])


def _scaled_rotation(q: Array, w: Array) -> Array:
    """Rotations ``q (N, 4)`` scaled by weights ``w (N,)`` in [0, 1] (slerp from identity)."""
    return rot.exp(rot.log(q) * w[:, None])


def hinge_axes(leg: Leg, pos: Array, grot: Array, forward: Array) -> Array:
    """``(F, 3)`` unit world directions of one leg's knee hinge axis in each frame: the direction
    of ``thigh x shin`` (the axis a bent knee turns about, shin swinging back) averaged over the
    motion in the thigh's own frame (the hip joint's global rotation ``grot (F, J, 4)``), weighted
    by how much the knee bends (the sine of its angle), and turned with the thigh. When the knee
    hardly ever bends (average sine below :data:`HINGE_MIN_SIN`), the axis that bends it towards
    the body's ``forward (F, 3)`` instead (shin swinging back). ``pos (F, J, 3)`` global
    positions."""
    thigh = pos[:, leg.knee] - pos[:, leg.hip]
    shin = pos[:, leg.ankle] - pos[:, leg.knee]
    scale = norms(thigh) * norms(shin)
    hip = grot[:, leg.hip]
    mean = rot.rotate(rot.inverse(hip), cross(thigh, shin)).sum(axis=0)
    size = float(np.linalg.norm(mean))
    if size > HINGE_MIN_SIN * float(scale.sum()):
        return np.asarray(rot.rotate(hip, np.broadcast_to(mean / size, thigh.shape)))
    axis = cross(thigh, -forward)
    return np.asarray(axis / np.maximum(norms(axis), 1e-300)[:, None])


def knee_axes(thigh: Array, shin: Array, hinge: Array) -> Array:
    """``(N, 3)`` unit axes to bend knees about, perpendicular to the thighs: the plane the knee
    bends in (``thigh x shin``) where it clearly bends forward (the sine of its angle, signed by
    the ``hinge`` axis of :func:`hinge_axes`, at least :data:`KNEE_PLANE_SIN`), the hinge axis
    where it is straight or bent backwards, and in between a smoothstep blend of both. Unlike the
    plane alone, which turns arbitrarily as the knee passes through straight (a target that
    bends a straight knee would bend it sideways or backwards in one frame and forwards in the
    next: a joint-acceleration spike), this is continuous in the pose. ``thigh``, ``shin``
    ``(N, 3)`` hip-to-knee and knee-to-ankle vectors."""
    t_hat = thigh / np.maximum(norms(thigh), 1e-300)[:, None]
    bent = cross(t_hat, shin / np.maximum(norms(shin), 1e-300)[:, None])  # |bent| = sin(angle)
    pole = hinge - np.einsum("ij,ij->i", hinge, t_hat)[:, None] * t_hat
    pole /= np.maximum(norms(pole), 1e-300)[:, None]
    size = norms(bent)
    plane = bent / np.maximum(size, 1e-300)[:, None]
    b = _smoothstep(np.einsum("ij,ij->i", bent, pole) / KNEE_PLANE_SIN)[:, None]
    axis = b * plane + (1.0 - b) * pole  # b > 0 only where plane . pole > 0: never zero
    return np.asarray(axis / np.maximum(norms(axis), 1e-300)[:, None])


def _solve_leg(
    leg: Leg,
    skeleton: Skeleton,
    pos: Array,
    grot: Array,
    local: Array,
    frames: npt.NDArray[np.intp],
    ankle_target: Array,
    toe_target: Array | None,
    toe_weight: Array | None,
    hinge: Array,
    toe_floor: float | None = None,
) -> tuple[Array, Array | None]:
    """Solve one leg on ``frames``: write new local rotations into ``local``; return the ankle
    positions reached ``(N, 3)`` and, with a toe, the toe positions reached. ``hinge (N, 3)``: the
    knee's hinge axis in those frames (:func:`hinge_axes`); ``toe_floor``: the lowest height the
    toe may end at (:func:`_lift_toe`), none when ``None``."""
    par = skeleton.parents
    h = pos[frames, leg.hip]
    k = pos[frames, leg.knee]
    a = pos[frames, leg.ankle]
    thigh = k - h
    shin = a - k
    l1 = norms(thigh)
    l2 = norms(shin)
    to_target = ankle_target - h
    dist = norms(to_target)
    lo = np.abs(l1 - l2) * (1.0 + 1e-6) + 1e-9 * (l1 + l2)
    hi = (l1 + l2) * (1.0 - 1e-6)
    # soft IK: past the frame's own extension (or 97% of full reach), ease towards full reach
    base = np.minimum(np.maximum(norms(a - h), SOFT_IK_START * hi), hi)
    room = np.maximum(hi - base, 1e-12)
    over = dist > base
    dist = np.where(over, base + room * (1.0 - np.exp(-np.maximum(dist - base, 0.0) / room)), dist)
    dist = np.clip(dist, lo, hi)
    # 1. knee: angle between thigh and shin directions (0 = straight) from the law of cosines,
    # bent about the knee's bending axis (knee_axes: continuous through a straight knee).
    cos_des = (dist**2 - l1**2 - l2**2) / np.maximum(2.0 * l1 * l2, 1e-300)
    phi_des = np.arccos(np.clip(cos_des, -1.0, 1.0))
    axis = knee_axes(thigh, shin, hinge)
    t_hat = thigh / np.maximum(l1, 1e-300)[:, None]
    side = cross(axis, t_hat)  # unit, perpendicular to the thigh, towards where the shin bends
    shin_new = l2[:, None] * (np.cos(phi_des)[:, None] * t_hat + np.sin(phi_des)[:, None] * side)
    q_knee = _arc(shin, shin_new)
    a1 = k + rot.rotate(q_knee, shin)
    # 2. hip: shortest arc from the bent leg's ankle direction to the target direction.
    q_hip = _arc(a1 - h, to_target)
    reached = h + rot.rotate(q_hip, a1 - h)
    # 3. ankle: keep the foot's global orientation; turn it so a pinned toe lands.
    g_ankle = grot[frames, leg.ankle]
    toe_reached = None
    if leg.toe >= 0:
        foot = pos[frames, leg.toe] - a
        if toe_target is not None and toe_weight is not None:
            q_toe = _scaled_rotation(_arc(foot, _toe_direction(toe_target - reached, foot)), toe_weight)
            g_ankle = rot.multiply(q_toe, g_ankle)
            foot = rot.rotate(q_toe, foot)
        if toe_floor is not None:
            q_lift = _lift_toe(reached, foot, toe_floor)
            g_ankle = rot.multiply(q_lift, g_ankle)
            foot = rot.rotate(q_lift, foot)
        toe_reached = reached + foot
    g_hip_new = rot.multiply(q_hip, grot[frames, leg.hip])
    hip_parent = grot[frames, par[leg.hip]]
    local[frames, leg.hip] = rot.multiply(rot.inverse(hip_parent), g_hip_new)
    knee_parent = grot[frames, par[leg.knee]]
    local[frames, leg.knee] = rot.multiply(
        rot.inverse(knee_parent), rot.multiply(q_knee, grot[frames, leg.knee])
    )
    ankle_parent_new = rot.multiply(q_hip, rot.multiply(q_knee, grot[frames, par[leg.ankle]]))
    local[frames, leg.ankle] = rot.multiply(rot.inverse(ankle_parent_new), g_ankle)
    return np.asarray(reached), toe_reached


def _lift_toe(ankle: Array, foot: Array, floor: float) -> Array:
    """``(N, 4)`` rotations of the foot about its ankle that keep a toe at ``ankle + foot`` (both
    ``(N, 3)``) from ending below ``floor``: identity where it is at or above it, elsewhere the
    shortest arc tilting the foot up (same heading) until the toe is at ``floor`` (as high as it
    goes when the floor is out of the foot's reach). The last resort of the floor, where the
    leg could not lift the ankle as far as the toe needed (:func:`_solve_all`)."""
    q = np.zeros((foot.shape[0], 4))
    q[:, 3] = 1.0
    low = ankle[:, 1] + foot[:, 1] < floor
    if not low.any():
        return q
    f = foot[low]
    length = np.maximum(norms(f), 1e-12)
    uy = np.clip((floor - ankle[low, 1]) / length, -1.0, 1.0)
    h = f[:, [0, 2]]
    hn = norms(h)
    flat = hn > 1e-9 * length  # a foot pointing straight down has no heading: tilt it along x
    h = np.where(flat[:, None], h / np.maximum(hn, 1e-300)[:, None], np.array([1.0, 0.0]))
    side = np.sqrt(np.maximum(1.0 - uy**2, 0.0))
    up = length[:, None] * np.stack((h[:, 0] * side, uy, h[:, 1] * side), axis=-1)
    q[low] = _arc(f, up)
    return q


def _toe_direction(to_target: Array, foot: Array) -> Array:
    """The unit direction ``(N, 3)`` to point the foot (ankle to toe) for a toe target
    ``to_target`` away from the ankle reached: at the target, but never so steeply down that the
    toe ends more than a tenth of the foot's length below the target's height (an ankle that could
    not reach its own place, e.g. a leg that cannot stretch as far as a smoothed cut asks, would
    otherwise drive the toe into the floor). A smooth maximum keeps the direction continuous."""
    length = np.maximum(norms(foot), 1e-12)
    norm = np.maximum(norms(to_target), 1e-12)
    point = to_target[:, 1] / norm
    floor = np.clip(to_target[:, 1] / length - 0.1, -1.0, 1.0)
    uy = np.clip(0.5 * (point + floor + np.sqrt((point - floor) ** 2 + 0.05**2)), -1.0, 1.0)
    h = to_target[:, [0, 2]]
    hn = np.maximum(norms(h)[..., None], 1e-12)
    horizontal = h / hn * np.sqrt(np.maximum(1.0 - uy**2, 0.0))[:, None]
    return np.stack((horizontal[:, 0], uy, horizontal[:, 1]), axis=-1)


def _forward(motion: Motion, pos: Array) -> Array:
    """``(F, 3)`` the body's forward direction on the floor (knees that never bend bend towards it)."""
    from .ground import heading  # local import: ground imports contacts-free modules only

    hd = heading(motion, pos)
    return np.stack((np.sin(hd), np.zeros_like(hd), np.cos(hd)), axis=-1)


def _solve_all(
    motion: Motion,
    legs: tuple[Leg, ...],
    pos: Array,
    grot: Array,
    corr: Array,
    weight: Array,
    forward: Array,
    floor: Array | None = None,
) -> tuple[Array, Array, Array]:
    """Solve every leg; returns new local rotations, reached ankle targets' residuals ``(F, K)``
    and the ankle error vectors ``(F, L, 3)`` (target - reached). ``floor (K,)``: the contact
    joints' lowest heights; a toe among them that the solved leg carries lower lifts its whole
    foot (the ankle target rises with it, so the errors are measured from the lifted targets)."""
    local = np.array(motion.rotations, copy=True)
    n = motion.num_frames
    residual = np.zeros(weight.shape)
    errors = np.zeros((n, len(legs), 3))
    for li, leg in enumerate(legs):
        has_a, has_t = leg.ankle_slot >= 0, leg.toe_slot >= 0
        wa = weight[:, leg.ankle_slot] if has_a else np.zeros(n)
        wt = weight[:, leg.toe_slot] if has_t else np.zeros(n)
        frames = np.flatnonzero((wa > 0) | (wt > 0))
        if frames.size == 0:
            continue
        shift = np.zeros((frames.size, 3))
        if has_a:
            shift += corr[frames, leg.ankle_slot]
        if has_t:
            shift += (1.0 - wa[frames])[:, None] * corr[frames, leg.toe_slot]
        target = pos[frames, leg.ankle] + shift
        toe_target = pos[frames, leg.toe] + corr[frames, leg.toe_slot] if has_t else None
        hinge = hinge_axes(leg, pos, grot, forward)[frames]
        toe_weight = wt[frames] if has_t else None
        reached, toe_reached = _solve_leg(
            leg, motion.skeleton, pos, grot, local, frames, target, toe_target, toe_weight, hinge
        )
        if (
            floor is not None
            and toe_target is not None
            and toe_weight is not None
            and toe_reached is not None
        ):
            # a toe the solved leg carries below its floor: the whole foot rises by what it lacks
            # (ankle and toe targets alike, so the foot keeps its orientation and both keep their
            # floor position), and what the leg cannot reach is tilted up (_lift_toe)
            toe_floor = float(floor[leg.toe_slot])
            sink = toe_reached[:, 1] < toe_floor
            if sink.any():
                rise = toe_floor - toe_reached[sink, 1]
                target, toe_target = target.copy(), toe_target.copy()
                target[sink, 1] += rise
                toe_target[sink, 1] += rise
                lifted, toe_lifted = _solve_leg(
                    leg,
                    motion.skeleton,
                    pos,
                    grot,
                    local,
                    frames[sink],
                    target[sink],
                    toe_target[sink],
                    toe_weight[sink],
                    hinge[sink],
                    toe_floor,
                )
                reached[sink] = lifted
                if toe_lifted is not None:
                    toe_reached[sink] = toe_lifted
        errors[frames, li] = target - reached
        if has_a:
            full = wa[frames] >= 1.0
            residual[frames[full], leg.ankle_slot] = norms(errors[frames[full], li])
        if toe_target is not None and toe_reached is not None:
            full = wt[frames] >= 1.0
            residual[frames[full], leg.toe_slot] = np.linalg.norm(
                toe_target[full] - toe_reached[full], axis=-1
            )
    return local, residual, errors


def solve_foot_skate(
    motion: Motion,
    contacts: tuple[npt.NDArray[np.intp], npt.NDArray[np.bool_]] | None = None,
    *,
    blend_s: float = 0.1,
    root_adjust: bool = False,
    max_root_shift_m: float = 0.05,
    heights: Array | None = None,
    floor: Array | None = None,
    fk: tuple[Array, Array] | None = None,
    horizontal: bool = True,
) -> FootSkateResult:
    """Pin feet during contacts by leg IK; the full result (see :func:`remove_foot_skate`).

    Parameters
    ----------
    motion:
        Any motion whose foot joints hang under hip-knee-ankle chains (units as in the motion).
    contacts:
        ``(joints (K,), flags (F, K))`` as returned by :func:`motion.contacts.detect_contacts`
        (the default when ``None``): which joints are planted in which frames.
    blend_s:
        Seconds over which each pin fades in before a contact run and out after it (>= 0).
    root_adjust:
        When a pinned foot is out of the leg's reach, move the root by the missing distance
        (smoothed over ``blend_s``, at most ``max_root_shift_m`` metres) and solve again.
    max_root_shift_m:
        Largest root translation, metres (converted with ``motion.metres_per_unit``).
    heights:
        ``(F, K)`` the height (motion units) each contact joint should rest at in each frame,
        e.g. its height in the source clips before cuts were smoothed (smoothing a cut between
        clips of different hip heights lowers or raises the feet); default: the joints' own.
    floor:
        ``(K,)`` the lowest height (motion units) each contact joint may reach, in any frame: a
        joint that would go lower (a blended or smoothed leg swinging through the floor) is lifted
        to it by the same leg IK, height only. The lift is zero where the joint is above, so it
        fades in and out with the joint's own motion. A toe among them that the solved leg would
        still carry below its floor lifts its whole foot (step 3 of the module docstring).
    fk:
        The motion's :meth:`Motion.fk` (``positions (F, J, 3)``, ``rotations (F, J, 4)``) when the
        caller has it already.
    horizontal:
        Pin planted feet in place (the default, "lock"); ``False`` pins their height only, so that
        planted feet rest on their floor but keep their own path over it ("grounding"). ``floor``
        applies either way.
    """
    if not (np.isfinite(blend_s) and blend_s >= 0):
        raise MotionError(f"blend_s must be a non-negative number of seconds, got {blend_s}")
    if not (np.isfinite(max_root_shift_m) and max_root_shift_m >= 0):
        raise MotionError(f"max_root_shift_m must be >= 0 metres, got {max_root_shift_m}")
    if contacts is None:
        contacts = detect_contacts(motion)
    joints = np.asarray(contacts[0], dtype=np.intp).reshape(-1)
    flags = np.asarray(contacts[1], dtype=bool)
    n = motion.num_frames
    if flags.shape != (n, joints.size):
        raise MotionError(f"contact flags must be (F, K) = ({n}, {joints.size}), got {flags.shape}")
    if heights is not None and np.shape(heights) != (n, joints.size):
        raise MotionError(f"rest heights must be (F, K) = ({n}, {joints.size}), got {np.shape(heights)}")
    if floor is not None and np.shape(floor) != (joints.size,):
        raise MotionError(f"floor heights must be (K,) = ({joints.size},), got {np.shape(floor)}")
    no_shift = np.zeros((n, 3))
    if not flags.any() and floor is None:
        return FootSkateResult(motion, leg_chains(motion, joints), np.zeros(flags.shape), no_shift)
    pos, grot = motion.fk() if fk is None else fk  # (F, J, 3), (F, J, 4): gathered per joint
    legs = leg_chains(motion, joints, pos[0])
    if not legs:
        return FootSkateResult(motion, legs, np.zeros(flags.shape), no_shift)
    blend = int(round(blend_s * motion.fps))
    corr, weight = _pin_targets(motion, pos, joints, flags, blend, heights, floor, horizontal)
    forward = _forward(motion, pos)
    local, residual, errors = _solve_all(motion, legs, pos, grot, corr, weight, forward, floor)
    root_shift = no_shift
    limit = max_root_shift_m / motion.metres_per_unit
    if root_adjust and limit > 0 and residual.max() > 1e-6 * limit:
        root_shift = _root_shift(errors, blend, limit)
        pos = pos + root_shift[:, None, :]
        # targets are world positions: the corrections are relative to the shifted pose
        corr -= weight[:, :, None] * root_shift[:, None, :]
        local, residual, _ = _solve_all(motion, legs, pos, grot, corr, weight, forward, floor)
    out = replace(motion, rotations=local, root_positions=motion.root_positions + root_shift)
    return FootSkateResult(out, legs, residual, root_shift)


def _pin_targets(
    motion: Motion,
    pos: Array,
    joints: npt.NDArray[np.intp],
    flags: npt.NDArray[np.bool_],
    blend: int,
    heights: Array | None,
    floor: Array | None,
    horizontal: bool = True,
) -> tuple[Array, Array]:
    """Where each contact joint should be: ``(F, K, 3)`` corrections of its global position
    (motion units) and their ``(F, K)`` weights, pinned over its contact runs (jumps widened,
    faded over ``blend`` frames; height only without ``horizontal``) and lifted above ``floor``."""
    n = motion.num_frames
    corr = np.zeros((n, joints.size, 3))
    weight = np.zeros((n, joints.size))
    frames_per_unit = motion.fps * motion.metres_per_unit / PIN_TRAVEL_M_S
    for slot, j in enumerate(joints):
        runs = widen_jumps(pos[:, j], flags[:, slot], frames_per_unit, 2 * blend)
        rest = None if heights is None else heights[:, slot]
        corr[:, slot], weight[:, slot] = pin_corrections(pos[:, j], runs, blend, rest)
        if not horizontal:
            corr[:, slot, 0] = corr[:, slot, 2] = 0.0
        if floor is not None:
            # never below the floor: lift the joint (height only) wherever it would sink under it
            lift = np.maximum(float(floor[slot]) - (pos[:, j, 1] + corr[:, slot, 1]), 0.0)
            corr[:, slot, 1] += lift
            weight[:, slot] = np.where(lift > 0, 1.0, weight[:, slot])
    return corr, weight


def _root_shift(errors: Array, blend: int, limit: float) -> Array:
    """``(F, 3)`` the root translation that moves the body towards the largest unreached error
    of each frame (``errors (F, K, 3)``), smoothed over ``blend`` frames and at most ``limit``."""
    n = errors.shape[0]
    mag = norms(errors)
    worst = errors[np.arange(n), np.argmax(mag, axis=1)]
    width = max(blend, 1)
    kernel = _smoothstep(1.0 - np.abs(np.arange(-width, width + 1)) / (width + 1))
    kernel /= kernel.sum()
    padded = np.pad(worst, ((width, width), (0, 0)), mode="edge")
    shift = np.stack([np.convolve(padded[:, c], kernel, mode="valid") for c in range(3)], axis=-1)
    norm = norms(shift)[..., None]
    shift *= np.minimum(1.0, limit / np.maximum(norm, 1e-300))
    return shift


def remove_foot_skate(
    motion: Motion,
    contacts: tuple[npt.NDArray[np.intp], npt.NDArray[np.bool_]] | None = None,
    *,
    blend_s: float = 0.1,
    root_adjust: bool = False,
    max_root_shift_m: float = 0.05,
    heights: Array | None = None,
    floor: Array | None = None,
    fk: tuple[Array, Array] | None = None,
    horizontal: bool = True,
) -> Motion:
    """The motion with planted feet kept in place (a pure function; the input is not modified).

    Each contact run of each foot joint pins that joint to the mean of its global positions over
    the run (``x, z`` and height, motion units, Y up); hips, knees and ankles are re-solved by
    analytic two-bone IK (knee bending in its original plane), with the correction faded in and
    out over ``blend_s`` seconds around each run. Only the local rotations of leg joints change
    (bone lengths are preserved); the root is unchanged unless ``root_adjust`` (see
    :func:`solve_foot_skate`, which also reports what could not be reached).

    Parameters
    ----------
    motion:
        The motion to clean.
    contacts:
        ``(joints (K,), flags (F, K))``; default :func:`motion.contacts.detect_contacts`.
    blend_s:
        Fade time in seconds around each contact run.
    heights, floor:
        ``(F, K)`` rest heights and ``(K,)`` lowest heights of the contact joints (see
        :func:`solve_foot_skate`).
    fk:
        The motion's :meth:`Motion.fk` when the caller has it already.
    horizontal:
        ``False``: planted feet keep their own floor path, only their height is pinned
        (:func:`solve_foot_skate`).

    Raises
    ------
    MotionError
        When a contact joint has no hip-knee-ankle chain above it, or the flags' shape is wrong.

    Examples
    --------
    >>> from motion.io import load_motion
    >>> from motion.samples import sample_path
    >>> walk = load_motion(sample_path("walk")).slice(1, 200)
    >>> clean = remove_foot_skate(walk)
    """
    return solve_foot_skate(
        motion,
        contacts,
        blend_s=blend_s,
        root_adjust=root_adjust,
        max_root_shift_m=max_root_shift_m,
        heights=heights,
        floor=floor,
        fk=fk,
        horizontal=horizontal,
    ).motion


def move_feet(
    motion: Motion,
    ankles: npt.NDArray[np.intp],
    shifts: Array,
    *,
    fk: tuple[Array, Array] | None = None,
) -> Motion:
    """``motion`` with each ankle ``ankles (L,)`` moved by ``shifts (F, L, 3)`` (world, motion
    units) by its leg's two-bone IK (knee and hip, as :func:`solve_foot_skate` solves them): the
    foot keeps its world orientation, so everything below the ankle moves by the same shift. A
    leg keeps its exact rotations in frames where its shift is zero. A target out of the leg's
    reach in that frame (beyond its own extension or 97 % of its full length, where soft IK
    would ease it) is brought back within reach vertically, so that the ankle still keeps its
    place on the floor's plane: what the leg cannot reach is left undone, in height.

    ``fk``: the motion's :meth:`Motion.fk` when the caller has it already. Raises
    :class:`MotionError` for an ankle with no hip-knee-ankle chain or shifts of the wrong shape."""
    joints = np.asarray(ankles, dtype=np.intp).reshape(-1)
    if np.shape(shifts) != (motion.num_frames, joints.size, 3):
        raise MotionError(
            f"foot shifts must be (F, L, 3) = ({motion.num_frames}, {joints.size}, 3), got {np.shape(shifts)}"
        )
    weight = (np.abs(shifts).max(axis=-1) > 0).astype(np.float64)
    if not weight.any():
        return motion
    pos, grot = motion.fk() if fk is None else fk
    legs = leg_chains(motion, joints, pos[0])
    if any(leg.toe >= 0 for leg in legs):
        raise MotionError("move_feet moves ankles: pass no toe joints")
    corr = np.array(shifts, dtype=np.float64, copy=True)
    for leg in legs:
        slot = leg.ankle_slot
        h, k, a = pos[:, leg.hip], pos[:, leg.knee], pos[:, leg.ankle]
        full = (norms(k - h) + norms(a - k)) * (1.0 - 1e-6)
        reach = np.minimum(np.maximum(norms(a - h), SOFT_IK_START * full), full) * (1.0 - 1e-9)
        d = a + corr[:, slot] - h
        flat = np.hypot(d[:, 0], d[:, 2])
        far = (norms(d) > reach) & (flat < reach)
        if far.any():  # the lower point of the vertical line through the target within reach
            low = h[far, 1] - np.sqrt(reach[far] ** 2 - flat[far] ** 2)
            high = h[far, 1] + np.sqrt(reach[far] ** 2 - flat[far] ** 2)
            y = a[far, 1] + corr[far, slot, 1]
            corr[far, slot, 1] = np.clip(y, low, high) - a[far, 1]
    local, _, _ = _solve_all(motion, legs, pos, grot, corr, weight, _forward(motion, pos))
    return replace(motion, rotations=local)
