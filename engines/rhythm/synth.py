"""Synthesis (Kim, Park & Shin 2003, Sec. 5): walk the movement transition graph while the music
lasts, blend each node's movements, time-warp them onto the music beats and stitch them.

Everything is vectorized over characters ``C`` (a crowd shares one music clock, so the time warp
is the same for all): per movement, a character draws its next node from ``P``, gets blend
weights from its target speed/turn, and the movement is rendered at the output frames that fall
in its beats by gathering precomputed movement frames (linear between frames, quaternions
blended by normalized weighted sums after sign alignment at build time).

Joins: the next movement is placed where the previous one ended (floor position and heading);
the remaining difference of posture (root position in the placement frame and every joint's
rotation, as a rotation vector) is added at the start of the new movement and faded out over
``join_beats`` beats with a smoothstep, so the motion is continuous at every join.

Time warp: within music beat ``k`` (from ``b_k`` to ``b_k+1``) the movement frame is
``u = P (k mod B + s(x))`` with ``x`` the fraction of the beat elapsed and
``s(x) = x - a sin(2 pi x) / (2 pi)`` (``a`` = ``accent``): ``s`` is monotone, ``s(0) = 0``,
``s(1) = 1``, so every motion beat lands exactly on its music beat; ``a > 0`` slows the motion
around the beat (rate ``1 - a``) and speeds it between beats (``1 + a``), accentuating the beat
as the speed minimum the eye (and the beat-align scores) look for. ``a = 0`` is the paper's linear warp.
Since the accent speeds the motion up between beats (up to ``1 + a`` times), each movement's
accent is lowered where it would drive the body faster, or turn it faster, than the fastest
example (:func:`bounded_accent`); the accent used is in each movement's plan.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from motion import rotations as rot
from motion.rotations import rotate_floor

from .beatkeys import warp_frames
from .blend import GroupBlender, blend_weights, one_hot

Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

CLARITY_PREFERENCE = 4.0
"""Movements are chosen in proportion to their beat clarity to this power (times the graph's
transition probability)."""
CLARITY_FLOOR = 0.05
"""Beat clarity below this counts as this much (every movement of the graph stays reachable)."""
PARTNER_JOIN_SPEED = 1.0
"""m/s: the fastest a couple's partner is moved by its join offset (:func:`partner_fade_frames`)."""
PARTNER_JOIN_TURN = np.radians(240.0)
"""rad/s: the fastest a couple's partner is turned by its join offset."""
PARTNER_FIT_FLOOR = 1e-6
"""Least weight of a movement in :func:`partner_fit` (every transition stays possible)."""
GROUP_FLOOR = 0.1
"""A group's preference (its members' mean, relative to the most preferred group's) counts at
least this much, so every transition of the movement graph, learned or added by a choreographer's
edit, is still danced (a floor near 0 would silence groups of unclear beats: measured, an added
transition was never taken in 40 dances; beat alignment with ``accent: 0`` stays >= 0.5)."""


def member_preference(clarity: Array) -> Array:
    """``(M,)`` how much each movement is preferred: its beat clarity to the power
    ``CLARITY_PREFERENCE``, at least ``CLARITY_FLOOR`` of it."""
    return np.asarray(np.maximum(clarity, CLARITY_FLOOR) ** CLARITY_PREFERENCE, dtype=np.float64)


def group_preference(pref: Array, counts: npt.NDArray[np.integer[Any]]) -> Array:
    """``(K,)`` the factor the next group's transition probability is multiplied by: its members'
    mean preference ``pref`` ``(K, G)`` (0 for padding; ``counts`` ``(K,)`` members per group)
    relative to the most preferred group's, at least ``GROUP_FLOOR``."""
    mean = pref.sum(axis=1) / np.maximum(counts, 1)
    return np.asarray(np.maximum(mean / max(float(mean.max()), 1e-12), GROUP_FLOOR), dtype=np.float64)


def draw_probabilities(p: Array, clarity: Array, labels: IntArray) -> Array:
    """``(K, K)`` the probability synthesis draws each transition with (free dancing): the graph's
    ``p`` ``(K, K)`` (or start probabilities ``(K,)``, giving ``(1, K)``) times the target group's
    preference (:func:`group_preference`), rows renormalised.
    ``clarity`` ``(M,)`` and ``labels`` ``(M,)`` (each movement's group) as stored at build."""
    k = p.shape[-1]
    counts = np.bincount(labels, minlength=k)
    sums = np.bincount(labels, weights=member_preference(clarity), minlength=k)
    pref: Array = np.asarray(sums, dtype=np.float64)[:, None]
    w = np.atleast_2d(p) * group_preference(pref, counts)[None, :]
    w = w * (counts[None, :] > 0)
    return np.asarray(w / np.maximum(w.sum(axis=1, keepdims=True), 1e-300))


TOO_FAST_WEIGHT = 0.01
"""How much a movement counts when, danced at the music's beat period, its floor speed or turn rate
would pass the examples' limit (:func:`too_fast`): the music does not allow it (KPS03 keeps a movement's
speed to its own tempo); not 0, so a dancer whose next groups are all too fast still goes on."""


@dataclass(frozen=True, slots=True)
class Tables:
    """What synthesis reads (loaded once per database).

    root ``(M, N, 3)``, rot ``(M, N, J, 4)`` (signs aligned to each group's medoid), jt
    ``(M, N, K, 3)``, partner_root/partner_rot or None, end_xz ``(M, 2)``, end_yaw ``(M,)``,
    params ``(M, 2)``, labels ``(M,)``, p ``(K, K)``, start ``(K,)``, blender, frames_per_beat
    ``P``, beats_per_movement ``B``, fps (database), period_s, src_clip ``(M,)``, src_frames ``(M, N)``,
    beat_keys ``(M, B + 1)`` movement frames of each movement's own beats and their clarity ``(M,)``
    (:mod:`engines.rhythm.beatkeys`).
    """

    @property
    def member_preference(self) -> Array:
        """``(K, G)`` how much each group member is preferred (its beat clarity to the power
        ``CLARITY_PREFERENCE``, a floor keeping every member possible; 0 for padding)."""
        m = self.blender.members
        pref = member_preference(self.clarity)
        return np.where(m >= 0, pref[np.maximum(m, 0)], 0.0)

    def plan_keys(self, plan: MovementPlan) -> Array:
        """``(B + 1,)`` beat keys of a planned movement: its blend's keys, averaged over the characters
        (a crowd shares one clock, hence one warp)."""
        keys = (self.beat_keys[plan.members] * plan.weights[..., None]).sum(axis=1)  # (C, B + 1)
        return np.asarray(keys.mean(axis=0))

    root: Array
    rot: Array
    jt: Array
    partner_root: Array | None
    partner_rot: Array | None
    end_xz: Array
    end_yaw: Array
    params: Array
    labels: IntArray
    p: Array
    start: Array
    blender: GroupBlender
    frames_per_beat: int
    beats_per_movement: int
    fps: float
    period_s: float
    src_clip: IntArray
    src_frames: Array
    beat_keys: Array
    clarity: Array

    @property
    def frames(self) -> int:
        return int(self.root.shape[1])

    @property
    def couples(self) -> bool:
        return self.partner_rot is not None


@dataclass(slots=True)
class Dancers:
    """State of ``C`` characters between movements (world frame, metres, radians).

    pos ``(C, 2)`` floor position of the body root, yaw ``(C,)`` heading, node ``(C,)`` current
    group (-1 before the first movement), last_root ``(C, 3)`` / last_rot ``(C, J, 4)`` the pose at
    the end of the previous movement (root rotation in the world), and the partner's likewise.
    """

    pos: Array
    yaw: Array
    node: IntArray
    last_root: Array | None = None
    last_rot: Array | None = None
    last_proot: Array | None = None
    last_prot: Array | None = None

    @property
    def count(self) -> int:
        return int(self.pos.shape[0])


@dataclass(slots=True)
class MovementPlan:
    """One movement of every character, ready to render at any movement frames ``u``."""

    members: IntArray  # (C, g)
    weights: Array  # (C, g)
    group: IntArray  # (C,)
    pos: Array  # (C, 2) placement
    yaw: Array  # (C,)
    extra_yaw: Array  # (C,) turn added progressively over the movement
    extra_xz: Array  # (C, 2) displacement added progressively (movement frame)
    d_root: Array  # (C, 3) join offset of the root (movement frame)
    d_rot: Array  # (C, J, 3) join offset of the rotations (rotation vectors)
    fade_frames: float  # movement frames over which the join offsets fade out
    d_proot: Array | None = None
    d_prot: Array | None = None
    pfade_frames: Array | None = None  # (C,) frames over which the partner's root offsets fade out


@dataclass(slots=True)
class Control:
    """Per-movement targets: ``speed (C,)`` m/s and desired ``heading (C,)`` radians, NaN = free."""

    speed: Array
    heading: Array


@dataclass(slots=True)
class Rendered:
    """Rendered frames of all characters: root ``(C, F, 3)``, rot ``(C, F, J, 4)``, jt ``(C, F, K, 3)``,
    partner arrays or None, and for provenance the dominant member ``(C, F)`` and its frame ``u (F,)``."""

    root: Array
    rot: Array
    jt: Array
    proot: Array | None
    prot: Array | None
    dominant: IntArray
    u: Array
    plans: list[dict[str, Any]] = field(default_factory=list)


def beat_phase(beats_s: Array, times_s: Array, beats_per_movement: int) -> tuple[IntArray, IntArray, Array]:
    """Per output time ``(F,)``: its movement, its beat within the movement and the fraction of
    that beat elapsed ``x`` in [0, 1] (times before the first beat hold the first frame; the final
    beat closes the last movement)."""
    b = np.asarray(beats_s, dtype=np.float64)
    k = np.clip(np.searchsorted(b, times_s, side="right") - 1, 0, b.size - 2)
    x = np.clip((times_s - b[k]) / (b[k + 1] - b[k]), 0.0, 1.0)
    return (k // beats_per_movement).astype(np.intp), (k % beats_per_movement).astype(np.intp), x


def accented(x: Array, accent: float) -> Array:
    """The accent warp within a beat, ``s(x) = x - a sin(2 pi x) / (2 pi)`` (module doc)."""
    return np.asarray(x - accent * np.sin(2.0 * np.pi * x) / (2.0 * np.pi))


def warp(
    beats_s: Array, times_s: Array, beats_per_movement: int, frames_per_beat: int, accent: float
) -> tuple[IntArray, Array]:
    """Movement index ``(F,)`` and movement frame ``u (F,)`` of every output time (module doc)."""
    mv, beat, x = beat_phase(beats_s, times_s, beats_per_movement)
    return mv, frames_per_beat * (beat + accented(x, accent))


@dataclass(frozen=True, slots=True)
class SpeedLimits:
    """The body's fastest floor speed (m/s) and turn rate (rad/s) in the examples, each measured
    over ``window_s`` (:mod:`motion.plausibility`)."""

    speed: float
    turn: float
    window_s: float


def bounded_accent(
    t: Tables, plan: MovementPlan, beat: IntArray, x: Array, accent: float, limits: SpeedLimits, fps: float
) -> float:
    """The largest accent up to ``accent`` with which a planned movement, rendered at the output
    frames whose beat and phase are ``beat``, ``x`` ``(F,)``, keeps the body (root) within
    ``limits`` (or no faster than the unaccented warp when that already exceeds them), found by
    bisection; with couples, the partner's root too. The accent speeds the motion up between beats
    (up to ``1 + a`` times), and a dancer does not move faster than the fastest example for the
    sake of an accent."""
    if accent <= 0 or x.size < 3:
        return max(accent, 0.0)
    w = max(1, int(round(limits.window_s * fps)))
    if x.size <= w:
        return accent

    bodies = [(t.root, t.rot)]
    if t.partner_root is not None and t.partner_rot is not None:
        bodies.append((t.partner_root, t.partner_rot))  # a couple's partner is held to them too

    def excess(a: float) -> float:
        u = warp_frames(t.plan_keys(plan), beat, accented(x, a))
        worst = 0.0
        for root_tab, rot_tab in bodies:
            root = _blend_at(root_tab, plan.members, plan.weights, u, False)[..., [0, 2]]  # (C, F, 2)
            q = _blend_at(rot_tab[:, :, :1], plan.members, plan.weights, u, True)[:, :, 0]  # (C, F, 4)
            yaw = np.unwrap(rot.yaw(q), axis=1)
            speed = np.linalg.norm(root[:, w:] - root[:, :-w], axis=-1).max() * fps / w
            turn = np.abs(yaw[:, w:] - yaw[:, :-w]).max() * fps / w
            worst = max(worst, speed / max(limits.speed, 1e-9), turn / max(limits.turn, 1e-9))
        return float(worst)

    allowed = max(1.0, excess(0.0))
    if excess(accent) <= allowed:
        return accent
    lo, hi = 0.0, accent
    for _ in range(6):
        mid = 0.5 * (lo + hi)
        if excess(mid) <= allowed:
            lo = mid
        else:
            hi = mid
    return lo


def beat_rates(t: Tables) -> Array:
    """``(M, 2)`` each movement's fastest floor travel (metres) and root turn (radians) per beat,
    over a quarter-beat window (the partner's too, for couples): divided by a beat period (s),
    the floor speed (m/s) and turn rate (rad/s) it reaches danced at that tempo, before any accent."""
    q = max(1, t.frames_per_beat // 4)
    worst = np.zeros((t.root.shape[0], 2))
    for root, rots in ((t.root, t.rot), (t.partner_root, t.partner_rot)):
        if root is None or rots is None:
            continue
        xz = root[:, :, [0, 2]]
        yaw = np.unwrap(rot.yaw(rots[:, :, 0]), axis=1)
        worst[:, 0] = np.maximum(worst[:, 0], np.linalg.norm(xz[:, q:] - xz[:, :-q], axis=-1).max(axis=1))
        worst[:, 1] = np.maximum(worst[:, 1], np.abs(yaw[:, q:] - yaw[:, :-q]).max(axis=1))
    return np.asarray(worst * t.frames_per_beat / q, dtype=np.float64)


def too_fast(rates: Array, period_s: float, limits: SpeedLimits, native_s: float) -> npt.NDArray[np.bool_]:
    """``(M,)`` the movements whose floor speed or turn rate at beat period ``period_s`` (``rates``
    from :func:`beat_rates`) passes ``limits`` and what they do at the examples' own period
    ``native_s`` (a movement danced at its own tempo is what the examples do: never too fast)."""
    at, own = rates / max(period_s, 1e-9), rates / max(native_s, 1e-9)
    cap = np.maximum(own, np.array([limits.speed, limits.turn]))
    return np.asarray((at > cap * (1.0 + 1e-9)).any(axis=1), dtype=np.bool_)


def _smooth_fade(u: Array, length: float | Array) -> Array:
    """1 at ``u = 0`` falling to 0 at ``u = length`` (smoothstep), 0 after (broadcast)."""
    x = np.clip(u / np.maximum(length, 1e-9), 0.0, 1.0)
    return np.asarray(1.0 - x * x * (3.0 - 2.0 * x))


def _blend_at(table: Array, members: IntArray, weights: Array, u: Array, normalize_quat: bool) -> Array:
    """Blend ``table (M, N, ...)`` over members ``(C, g)`` with ``weights`` at frames ``u (F,)``:
    ``(C, F, ...)`` (linear between neighbouring frames; normalized when quaternions)."""
    n = table.shape[1]
    i0 = np.minimum(np.floor(u).astype(np.intp), n - 2)
    a = (u - i0).reshape((1, -1) + (1,) * (table.ndim - 2))
    out = np.zeros((members.shape[0], u.size) + table.shape[2:])
    for g in range(members.shape[1]):
        m = members[:, g][:, None]
        v = table[m, i0[None, :]] * (1.0 - a) + table[m, i0[None, :] + 1] * a  # (C, F, ...)
        out += v * weights[:, g].reshape((-1,) + (1,) * (v.ndim - 1))
    if normalize_quat:
        out = out / np.linalg.norm(out, axis=-1, keepdims=True)
    return np.asarray(out)


def initial_dancers(count: int, formation: str, spacing: float, start_xz: Array, start_yaw: float) -> Dancers:
    """Characters placed in a formation around ``start_xz`` facing ``start_yaw``: ``grid`` (rows
    behind each other), ``line`` (side by side), ``column`` (one behind the other), ``circle``."""
    i = np.arange(count, dtype=np.float64)
    if formation == "line":
        local = np.stack((i - (count - 1) / 2, np.zeros(count)), axis=-1) * spacing
    elif formation == "column":
        local = np.stack((np.zeros(count), -i), axis=-1) * spacing
    elif formation == "circle":
        radius = max(spacing * count / (2 * np.pi), spacing if count > 1 else 0.0)
        ang = 2 * np.pi * i / max(count, 1)
        local = np.stack((radius * np.sin(ang), radius * np.cos(ang)), axis=-1)
    else:
        cols = int(np.ceil(np.sqrt(count)))
        local = np.stack((i % cols - (cols - 1) / 2, -(i // cols)), axis=-1) * spacing
    pos = start_xz[None, :] + rotate_floor(np.full(count, start_yaw), local)
    return Dancers(pos=pos, yaw=np.full(count, start_yaw), node=np.full(count, -1, dtype=np.intp))


def _sample_rows(cum: Array, rng: np.random.Generator) -> IntArray:
    """One draw from each row of cumulative probabilities ``cum (C, K)``."""
    draws = np.asarray(rng.random(cum.shape[0]), dtype=np.float64)
    r = draws[:, None] * cum[:, -1:]
    return np.asarray(np.minimum((r > cum).sum(axis=1), cum.shape[1] - 1), dtype=np.intp)


def plan_movement(
    t: Tables,
    d: Dancers,
    control: Control | None,
    rng: np.random.Generator,
    join_beats: float = 0.5,
    max_extra_turn: float = np.radians(45.0),
    max_extra_speed: float = 0.3,
    fast: npt.NDArray[np.bool_] | None = None,
) -> MovementPlan:
    """Choose each character's next node and blend, place it, and measure the join offsets.

    ``fast`` ``(M,)``: movements the music's tempo does not allow (:func:`too_fast`); they and
    groups of nothing else count ``TOO_FAST_WEIGHT`` times as much.

    ``control``: target speed and heading per character (NaN entries leave that parameter free).
    Without control a random member of the node is used as is (weight 1). With it, the blend
    weights come from the target ``(speed, turn)``; the turn the blend cannot reach and the
    difference between the blend's net displacement and the requested travel (speed along the
    desired heading) are added progressively over the movement (at most ``max_extra_turn``
    radians and ``max_extra_speed`` m/s; foot cleanup removes the sliding this causes).
    """
    c = d.count
    prob = t.start[None, :].repeat(c, 0) if (d.node < 0).all() else t.p[np.maximum(d.node, 0)]
    # movements whose speed dips on their beats are preferred (their beats land visibly on the
    # music): a group by its members' mean preference, then (free dancing) a member by its own
    pref = t.member_preference
    prob = prob * group_preference(pref, t.blender.counts)[None, :]
    if fast is not None and fast.any():
        m = t.blender.members
        allowed = np.where(m >= 0, ~fast[np.maximum(m, 0)], False)  # (K, G)
        pref = pref * np.where(allowed, 1.0, TOO_FAST_WEIGHT)
        prob = prob * np.where(allowed.any(axis=1), 1.0, TOO_FAST_WEIGHT)[None, :]
    member_fit = partner_fit(t, d)  # (C, M) or None
    if member_fit is not None:
        m = t.blender.members
        fit = np.where(m >= 0, member_fit[:, np.maximum(m, 0)], 0.0)  # (C, K, G)
        prob = prob * fit.max(axis=2)
    cum = np.cumsum(prob, axis=1)
    group = _sample_rows(cum, rng)  # the next node of the movement transition graph
    if control is None:
        within = pref[group] if member_fit is None else pref[group] * fit[np.arange(c), group]
        pick = _sample_rows(np.cumsum(within, axis=1), rng)
        members, weights = t.blender.members[group, pick][:, None], np.ones((c, 1))
        extra_yaw, extra_xz = np.zeros(c), np.zeros((c, 2))
    else:
        members, weights, extra_yaw, extra_xz = _steered_blend(
            t, d, group, control, rng, max_extra_turn, max_extra_speed
        )
    plan = MovementPlan(
        members=members,
        weights=weights,
        group=group,
        pos=d.pos.copy(),
        yaw=d.yaw.copy(),
        extra_yaw=extra_yaw,
        extra_xz=extra_xz,
        d_root=np.zeros((c, 3)),
        d_rot=np.zeros((c, t.rot.shape[2], 3)),
        fade_frames=join_beats * t.frames_per_beat,
    )
    _join_to_last(t, d, plan)
    _advance(t, d, plan)
    return plan


def partner_fit(t: Tables, d: Dancers) -> Array | None:
    """``(C, M)`` how well each movement continues a couple from where the partner is now (None
    without couples, or before the first movement): ``exp(-s / period)``, ``s`` the seconds the
    partner's join would take to fade out at :data:`PARTNER_JOIN_SPEED` and
    :data:`PARTNER_JOIN_TURN` (:func:`partner_fade_frames`), at least ``PARTNER_FIT_FLOOR``. The
    leader's next movement is chosen by the graph, which matches the leader's posture; where the
    pair stands relative to each other differs between movements by up to a metre and a half turn,
    and a partner carried that far at a join moves faster than any example."""
    if t.partner_root is None or t.partner_rot is None or d.last_proot is None or d.last_prot is None:
        return None
    rel = rotate_floor(-d.yaw, d.last_proot[:, [0, 2]] - d.pos)  # (C, 2) in the next placement
    yaw_now = rot.yaw(rot.multiply(rot.from_yaw(-d.yaw), d.last_prot[:, 0]))  # (C,)
    start = t.partner_root[:, 0][:, [0, 2]]  # (M, 2)
    dist = np.linalg.norm(rel[:, None, :] - start[None, :, :], axis=-1)  # (C, M)
    turn = np.abs(rot.wrap_angle(yaw_now[:, None] - rot.yaw(t.partner_rot[:, 0, 0])[None, :]))
    seconds = 1.5 * np.maximum(dist / PARTNER_JOIN_SPEED, turn / PARTNER_JOIN_TURN)
    return np.asarray(np.maximum(np.exp(-seconds / max(t.period_s, 1e-9)), PARTNER_FIT_FLOOR))


def _steered_blend(
    t: Tables,
    d: Dancers,
    group: IntArray,
    control: Control,
    rng: np.random.Generator,
    max_extra_turn: float,
    max_extra_speed: float,
) -> tuple[IntArray, Array, Array, Array]:
    """The members and blend weights of each character's group that best reach the requested
    ``(speed, turn)`` (a free parameter: a random member's), and the extra turn ``(C,)`` radians
    and travel ``(C, 2)`` metres (capped) still needed, added over the movement."""
    duration = t.beats_per_movement * t.period_s
    free_m, _ = one_hot(t.blender, group, rng)
    free = t.params[free_m[:, 0]]
    turn_goal = rot.wrap_angle(control.heading - d.yaw)
    target = np.stack(
        (
            np.where(np.isnan(control.speed), free[:, 0], control.speed),
            np.where(np.isnan(control.heading), free[:, 1], turn_goal),
        ),
        axis=-1,
    )
    members, weights = blend_weights(t.blender, group, target)
    got = (t.params[members] * weights[..., None]).sum(axis=1)
    steer = ~np.isnan(control.heading)
    extra_yaw = np.where(steer, np.clip(target[:, 1] - got[:, 1], -max_extra_turn, max_extra_turn), 0.0)
    # travel: the net displacement of the blend vs the one asked for (speed along the desired
    # heading), in the movement frame; the difference, capped, is added progressively
    rel = np.where(steer, turn_goal, 0.0)
    want = np.stack((np.sin(rel), np.cos(rel)), axis=-1) * (np.nan_to_num(control.speed) * duration)[:, None]
    got_xz = (t.end_xz[members] * weights[..., None]).sum(axis=1)
    miss = want - got_xz
    norm = np.linalg.norm(miss, axis=1, keepdims=True)
    miss = miss * np.minimum(1.0, max_extra_speed * duration / np.maximum(norm, 1e-12))
    extra_xz = np.where(np.isnan(control.speed)[:, None], 0.0, miss)
    return members, weights, extra_yaw, extra_xz


def _join_to_last(t: Tables, d: Dancers, plan: MovementPlan) -> None:
    """The offsets that take the new movement's first pose (and its partner's) to the dancers'
    last pose, faded out over the join (none for the first movement)."""
    if d.last_root is None or d.last_rot is None:
        return
    u0 = np.zeros(1)
    members, weights = plan.members, plan.weights
    root0 = _blend_at(t.root, members, weights, u0, False)[:, 0]
    rot0 = _blend_at(t.rot, members, weights, u0, True)[:, 0]
    plan.d_root, plan.d_rot = _join_offsets(plan, d.last_root, d.last_rot, root0, rot0)
    if (
        t.partner_root is not None
        and t.partner_rot is not None
        and d.last_proot is not None
        and d.last_prot is not None
    ):
        proot0 = _blend_at(t.partner_root, members, weights, u0, False)[:, 0]
        prot0 = _blend_at(t.partner_rot, members, weights, u0, True)[:, 0]
        plan.d_proot, plan.d_prot = _join_offsets(plan, d.last_proot, d.last_prot, proot0, prot0)
        plan.pfade_frames = partner_fade_frames(t, plan.d_proot, plan.d_prot, plan.fade_frames)


def partner_fade_frames(t: Tables, d_proot: Array, d_prot: Array, shortest: float) -> Array:
    """``(C,)`` movement frames over which each partner's join offsets (root ``(C, 3)`` metres,
    rotations ``(C, J, 3)``) fade out: at least ``shortest``, at most the whole movement, and long
    enough that the smoothstep (peak rate 1.5 times the mean) moves the partner's root by no more
    than :data:`PARTNER_JOIN_SPEED` and turns it by no more than :data:`PARTNER_JOIN_TURN`, at the
    database's tempo. The leader's offsets are centimetres (transitions match its posture), but
    where the pair stands differs between movements: the partner's can be a metre and a half turn."""
    dist = np.linalg.norm(d_proot[:, [0, 2]], axis=1)
    turn = np.linalg.norm(d_prot[:, 0], axis=1)
    seconds = 1.5 * np.maximum(dist / PARTNER_JOIN_SPEED, turn / PARTNER_JOIN_TURN)
    frames_per_s = t.frames_per_beat / max(t.period_s, 1e-9)
    return np.asarray(np.clip(seconds * frames_per_s, shortest, t.frames - 1.0))


def _advance(t: Tables, d: Dancers, plan: MovementPlan) -> None:
    """Move the dancers to the end of the planned movement: place, heading, node and last pose."""
    members, weights = plan.members, plan.weights
    end_xz = (t.end_xz[members] * weights[..., None]).sum(axis=1) + plan.extra_xz
    end_yaw = (t.end_yaw[members] * weights).sum(axis=1) + plan.extra_yaw
    d.pos = d.pos + rotate_floor(d.yaw, rotate_floor(plan.extra_yaw, end_xz))
    d.yaw = d.yaw + end_yaw
    d.node = plan.group
    last = render(t, plan, np.array([t.frames - 1.0]))
    d.last_root, d.last_rot = last.root[:, 0], last.rot[:, 0]
    if last.proot is not None and last.prot is not None:
        d.last_proot, d.last_prot = last.proot[:, 0], last.prot[:, 0]


def _join_offsets(
    plan: MovementPlan, last_root: Array, last_rot: Array, root0: Array, rot0: Array
) -> tuple[Array, Array]:
    """Root offset ``(C, 3)`` and rotation offsets ``(C, J, 3)`` taking the new movement's first
    pose to the previous movement's last pose, in the new movement's placement frame."""
    rel = last_root.copy()
    rel[:, [0, 2]] = rotate_floor(-plan.yaw, last_root[:, [0, 2]] - plan.pos)
    prev = last_rot.copy()
    prev[:, 0] = rot.multiply(rot.from_yaw(-plan.yaw), last_rot[:, 0])
    d_rot = rot.log(rot.multiply(prev, rot.conjugate(rot0)))
    return rel - root0, d_rot


def render(t: Tables, plan: MovementPlan, u: Array) -> Rendered:
    """The planned movement of every character at movement frames ``u (F,)`` in ``[0, N-1]``."""
    prog = u / (t.frames - 1)  # progress through the movement, for the extra turn/travel

    def place(
        root_tab: Array, rot_tab: Array, d_root: Array | None, d_rot: Array | None, length: float | Array
    ) -> tuple[Array, Array]:
        """Blend, add the join offsets (the root's and the root rotation's faded over ``length``
        movement frames, ``()`` or ``(C,)``; the other joints' over ``plan.fade_frames``), place."""
        root = _blend_at(root_tab, plan.members, plan.weights, u, False)  # (C, F, 3)
        q = _blend_at(rot_tab, plan.members, plan.weights, u, True)  # (C, F, J, 4)
        c = root.shape[0]
        fade = np.broadcast_to(_smooth_fade(u[None, :], np.reshape(length, (-1, 1))), (c, u.size))
        pose = np.broadcast_to(_smooth_fade(u, plan.fade_frames)[None, :], (c, u.size))
        active = (fade > 0).any(axis=0) | (pose > 0).any(axis=0)
        if d_root is not None and d_rot is not None and active.any():
            f, g = fade[:, active], pose[:, active]  # (C, A)
            root[:, active] += f[..., None] * d_root[:, None, :]
            scale = np.concatenate(
                (f[..., None], np.repeat(g[..., None], q.shape[2] - 1, axis=-1)), axis=-1
            )  # (C, A, J)
            q[:, active] = rot.multiply(rot.exp(scale[..., None] * d_rot[:, None]), q[:, active])
        turn = plan.yaw[:, None] + plan.extra_yaw[:, None] * prog[None, :]  # (C, F)
        xz = rotate_floor(plan.extra_yaw[:, None] * prog[None, :], root[..., [0, 2]])
        xz = xz + plan.extra_xz[:, None, :] * prog[None, :, None]
        world = root.copy()
        world[..., [0, 2]] = rotate_floor(turn, xz) + plan.pos[:, None, :]
        q[:, :, 0] = rot.multiply(rot.from_yaw(turn), q[:, :, 0])
        return world, q

    root, q = place(t.root, t.rot, plan.d_root, plan.d_rot, plan.fade_frames)
    proot = prot = None
    if t.partner_root is not None and t.partner_rot is not None:
        length = plan.fade_frames if plan.pfade_frames is None else plan.pfade_frames
        proot, prot = place(t.partner_root, t.partner_rot, plan.d_proot, plan.d_prot, length)
    jt = (
        _blend_at(t.jt, plan.members, plan.weights, u, False)
        if t.jt.shape[2]
        else np.zeros((plan.group.size, u.size, 0, 3))
    )
    dominant = np.broadcast_to(
        plan.members[np.arange(plan.group.size), np.argmax(plan.weights, axis=1)][:, None],
        (plan.group.size, u.size),
    )
    return Rendered(root, q, jt, proot, prot, np.asarray(dominant), u)


ControlFn = Any  # Callable[[int, Dancers], Control | None]: targets at a movement's first beat


def synthesize(
    t: Tables,
    beats_s: Array,
    fps: float,
    dancers: Dancers,
    rng: np.random.Generator,
    control: ControlFn | None = None,
    accent: float = 0.5,
    limits: SpeedLimits | None = None,
) -> Rendered:
    """Frames ``0 .. floor(beats[-1] * fps)`` of every character, movements time-warped onto the beats.

    ``control(beat_index, dancers)`` returns the targets for the movement starting at that beat
    (or None for free dancing). With ``limits``, movements too fast for the music's tempo are
    avoided (:func:`too_fast`) and each movement's accent is lowered as far as it must be to keep
    the body within them (:func:`bounded_accent`)."""
    b = np.asarray(beats_s, dtype=np.float64)
    n_frames = int(np.floor(b[-1] * fps + 1e-9)) + 1
    times = np.arange(n_frames) / fps
    mv_index, beat, x = beat_phase(b, times, t.beats_per_movement)
    u = np.empty(n_frames)
    n_moves = int(mv_index.max()) + 1
    c = dancers.count
    j = t.rot.shape[2]
    out_root = np.empty((c, n_frames, 3))
    out_rot = np.empty((c, n_frames, j, 4))
    out_jt = np.empty((c, n_frames, t.jt.shape[2], 3))
    out_proot = np.empty((c, n_frames, 3)) if t.couples else None
    out_prot = (
        np.empty((c, n_frames, j if t.partner_rot is None else t.partner_rot.shape[2], 4))
        if t.couples
        else None
    )
    dominant = np.empty((c, n_frames), dtype=np.intp)
    plans: list[dict[str, Any]] = []
    bounds = np.searchsorted(mv_index, np.arange(n_moves + 1))
    rates = beat_rates(t) if limits is not None else None
    per = t.beats_per_movement
    for m in range(n_moves):
        ctl = control(m * per, dancers) if control is not None else None
        fast = None
        if rates is not None and limits is not None:
            span = b[m * per : m * per + per + 1]
            period = float(np.median(np.diff(span))) if span.size > 1 else t.period_s
            fast = too_fast(rates, period, limits, t.period_s)
        plan = plan_movement(t, dancers, ctl, rng, fast=fast)
        s, e = int(bounds[m]), int(bounds[m + 1])
        if e <= s:
            continue
        a = accent if limits is None else bounded_accent(t, plan, beat[s:e], x[s:e], accent, limits, fps)
        u[s:e] = warp_frames(t.plan_keys(plan), beat[s:e], accented(x[s:e], a))
        r = render(t, plan, u[s:e])
        out_root[:, s:e], out_rot[:, s:e], out_jt[:, s:e] = r.root, r.rot, r.jt
        if out_proot is not None and out_prot is not None and r.proot is not None and r.prot is not None:
            out_proot[:, s:e], out_prot[:, s:e] = r.proot, r.prot
        dominant[:, s:e] = r.dominant
        plans.append(
            {
                "start_frame": s,
                "start_beat": m * t.beats_per_movement,
                "group": int(plan.group[0]),
                "members": [int(x) for x in plan.members[0]],
                "weights": [round(float(w), 4) for w in plan.weights[0]],
                "accent": round(float(a), 3),
            }
        )
    return Rendered(out_root, out_rot, out_jt, out_proot, out_prot, dominant, u, plans)
