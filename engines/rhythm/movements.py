"""Basic movements (Kim, Park & Shin 2003, Sec. 4.1): cutting, time-warping and normalizing.

Each example is cut at every ``beats_per_movement`` motion beats. A basic movement is resampled
so that every beat interval spans the same ``P`` frames (the beats are the key times of a
piecewise-linear time warp to the common beat period), then translated on the floor and rotated
about +Y so that its body root starts at the origin facing +Z (the paper's normalization, after
Kovar et al. 2002).

Arrays (``M`` movements, ``N = B * P + 1`` frames each, ``J`` joints, ``B`` beats per movement):

* ``root (M, N, 3)`` metres, root joint position in the movement frame (Y up);
* ``rot (M, N, J, 4)`` local joint rotations (x, y, z, w); the root's is expressed in the movement
  frame; signs continuous in time;
* ``src_frames (M, N)`` fractional source frame of every movement frame, ``src_clip (M,)``;
* ``end_xz (M, 2)``, ``end_yaw (M,)`` the body root's floor position and heading change at the
  last frame (the next movement's start), radians;
* ``params (M, 2)`` speed (m/s along an arc fitted to the root path) and turning angle (radians).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import PchipInterpolator

from motion import Motion, MotionError
from motion import rotations as rot
from motion.ground import body_root, heading
from motion.resample import sample_at
from motion.rotations import rotate_floor

Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


@dataclass(frozen=True, slots=True)
class Example:
    """One example dance: a motion, its motion beats (seconds) and an optional partner motion
    synchronized frame by frame with it (a couple)."""

    name: str
    motion: Motion
    beats_s: Array
    partner: Motion | None = None


@dataclass(frozen=True, slots=True)
class Movements:
    """Basic movements of a set of examples (shapes in the module docstring)."""

    root: Array
    rot: Array
    jt: Array
    src_clip: IntArray
    src_frames: Array
    index_in_clip: IntArray
    end_xz: Array
    end_yaw: Array
    params: Array
    frames_per_beat: int
    beats_per_movement: int
    period_s: float
    fps: float
    partner_root: Array | None = None
    partner_rot: Array | None = None

    @property
    def count(self) -> int:
        return int(self.root.shape[0])

    @property
    def frames(self) -> int:
        return int(self.root.shape[1])


def rotate_points_yaw(p: Array, angle: Array) -> Array:
    """Rotate points ``(..., 3)`` about +Y by ``angle`` (broadcast over the leading axes)."""
    out = np.array(p, dtype=np.float64, copy=True)
    out[..., [0, 2]] = rotate_floor(angle, p[..., [0, 2]])
    return out


MAX_BEAT_RATIO = 1.5
"""Largest ratio of a movement's longest to its shortest beat for a basic movement."""


def warp_frames(beats_s: Array, fps: float, beats_per_movement: int, frames_per_beat: int) -> Array:
    """``(C, N)`` fractional source frames of the ``C = (len(beats) - 1) // B`` movements of a clip.

    The time warp maps beat index to source time through the beats (the key times) with a
    monotone C1 cubic (PCHIP) instead of straight segments: the rate of the warp is continuous at
    every beat, so a speed minimum at a beat stays at that beat after time normalization (a
    piecewise-linear warp jumps in rate at the beats and pushes the minimum aside)."""
    b = np.asarray(beats_s, dtype=np.float64)
    bpm_, p = beats_per_movement, frames_per_beat
    count = (b.size - 1) // bpm_
    if count < 1:
        return np.zeros((0, bpm_ * p + 1))
    index = np.arange(count)[:, None] * bpm_ + np.arange(bpm_ * p + 1)[None, :] / p  # (C, N) beat index
    if b.size >= 3:
        times = PchipInterpolator(np.arange(b.size, dtype=np.float64), b)(index)
    else:
        times = b[0] + index * (b[1] - b[0])
    return np.asarray(times * fps)


def arc_parameters(xz: Array, yaw_change: Array, duration_s: float) -> Array:
    """``(M, 2)`` speed (m/s) and turning angle (radians) of each movement's floor path, fitted by
    the arc that leaves the origin facing +Z and reaches the end point ``xz[:, -1]`` while turning by
    ``yaw_change``: arc length = chord * (theta/2) / sin(theta/2) (a straight line when theta -> 0)."""
    chord = np.linalg.norm(xz[:, -1], axis=-1)
    half = 0.5 * np.asarray(yaw_change)
    ratio = np.where(np.abs(half) > 1e-6, half / np.where(np.abs(half) > 1e-6, np.sin(half), 1.0), 1.0)
    ratio = np.clip(ratio, 1.0, 5.0)  # turns on the spot are not arcs: bound the length
    return np.stack((chord * ratio / duration_s, yaw_change), axis=-1)


def _normalize(m: Motion, c: int, n: int, origin: Array, yaw0: Array) -> tuple[Array, Array]:
    """Root positions ``(C, N, 3)`` and rotations ``(C, N, J, 4)`` of ``C`` movements of ``N`` frames
    stacked in ``m``, moved by ``-origin (C, 2)`` on the floor and turned by ``-yaw0 (C,)``."""
    r = m.root_positions.reshape(c, n, 3).copy()
    r[..., [0, 2]] -= origin[:, None, :]
    r = rotate_points_yaw(r, -yaw0[:, None])
    q = m.rotations.reshape(c, n, m.num_joints, 4).copy()
    q[:, :, 0] = rot.multiply(rot.from_yaw(-yaw0)[:, None, :], q[:, :, 0])
    return r, rot.make_continuous(q, axis=1)


def extract_movements(examples: list[Example], beats_per_movement: int) -> Movements:
    """Cut, time-warp and normalize the basic movements of ``examples``.

    The common beat period is the median beat period of all examples; ``P`` is that period in
    frames (at least 4). Spans whose beats are irregular (the longest beat more than
    :data:`MAX_BEAT_RATIO` times the shortest: a missed or an extra beat) are not basic movements:
    normalizing them to equal beats would play part of them half again as fast, and they are left
    out (unless no span is regular). ``index_in_clip`` keeps each movement's place among its
    clip's spans, so gaps show where one was left out. Raises :class:`MotionError` when no example
    has ``beats_per_movement + 1`` beats.
    """
    if not examples:
        raise MotionError("no examples to cut into movements")
    fps = examples[0].motion.fps
    periods = np.concatenate([np.diff(e.beats_s) for e in examples if e.beats_s.size > 1])
    if periods.size == 0:
        raise MotionError("the examples have fewer than 2 motion beats each")
    period = float(np.median(periods))
    p = max(4, int(round(period * fps)))
    cuts = [
        cut
        for ci, ex in enumerate(examples)
        if (cut := _cut_example(ci, ex, fps, beats_per_movement, p)) is not None
    ]
    if not cuts:
        raise MotionError(
            f"no example has {beats_per_movement + 1} motion beats: nothing to cut into "
            f"{beats_per_movement}-beat movements"
        )
    keep = np.concatenate([cut.regular for cut in cuts])
    if not keep.any():
        keep[:] = True  # no clean span at all: irregular movements rather than none
    couples = [e.partner is not None for e in examples]
    if any(couples) and not all(couples):
        raise MotionError("examples must be all solo or all couples")

    def kept(arrays: list[npt.NDArray[Any] | None]) -> npt.NDArray[Any]:
        """The regular movements of all the examples, end to end (examples are all solo or all
        couples, so a partner's arrays are there for every example or for none)."""
        return np.asarray(np.concatenate([a for a in arrays if a is not None])[keep])

    end_xz, end_yaw = kept([cut.end_xz for cut in cuts]), kept([cut.end_yaw for cut in cuts])
    duration = beats_per_movement * period
    body_path = np.concatenate((np.zeros((end_xz.shape[0], 1, 2)), end_xz[:, None, :]), axis=1)
    partnered = any(cut.partner_root is not None for cut in cuts)
    return Movements(
        root=kept([cut.root for cut in cuts]),
        rot=kept([cut.rot for cut in cuts]),
        jt=kept([cut.jt for cut in cuts]),
        src_clip=kept([cut.src_clip for cut in cuts]),
        src_frames=kept([cut.src_frames for cut in cuts]),
        index_in_clip=kept([cut.index_in_clip for cut in cuts]),
        end_xz=end_xz,
        end_yaw=end_yaw,
        params=arc_parameters(body_path, end_yaw, duration),
        frames_per_beat=p,
        beats_per_movement=beats_per_movement,
        period_s=period,
        fps=fps,
        partner_root=kept([cut.partner_root for cut in cuts]) if partnered else None,
        partner_rot=kept([cut.partner_rot for cut in cuts]) if partnered else None,
    )


@dataclass(slots=True)
class _ClipMovements:
    """The ``C`` movements cut from one example, each ``n = beats x P`` frames, normalized (its
    first frame at the floor origin, facing +Z)."""

    root: Array  # (C, n, 3)
    rot: Array  # (C, n, J, 4)
    jt: Array  # (C, n, K, 3) joint translations
    partner_root: Array | None
    partner_rot: Array | None
    end_xz: Array  # (C, 2) where the body ends, in the movement's frame
    end_yaw: Array  # (C,) how far it turned, radians
    src_clip: IntArray  # (C,)
    src_frames: Array  # (C, n) source frame of every frame
    index_in_clip: IntArray  # (C,)
    regular: npt.NDArray[np.bool_]  # (C,) its beats are regular


def _cut_example(ci: int, ex: Example, fps: float, beats_per_movement: int, p: int) -> _ClipMovements | None:
    """Example ``ci`` cut at its beats into movements time-warped to ``p`` frames per beat (None
    when it has too few beats)."""
    b = np.asarray(ex.beats_s, dtype=np.float64)
    b = b[(b >= 0) & (b <= ex.motion.duration_s + 1e-9)]
    src = warp_frames(b, fps, beats_per_movement, p)
    if src.shape[0] == 0:
        return None
    src = np.clip(src, 0.0, ex.motion.num_frames - 1)
    spans = np.diff(b[: src.shape[0] * beats_per_movement + 1]).reshape(src.shape[0], beats_per_movement)
    c, n = src.shape
    sampled = sample_at(ex.motion, src.reshape(-1))
    pos = sampled.global_positions()
    yaw = heading(sampled, pos).reshape(c, n)
    # unwrap within each movement, relative to its first frame
    yaw = np.unwrap(yaw, axis=1)
    yaw0 = yaw[:, 0]
    body = pos[:, body_root(ex.motion.skeleton), :].reshape(c, n, 3)
    origin = body[:, 0, [0, 2]]  # (C, 2)
    r, q = _normalize(sampled, c, n, origin, yaw0)
    pr = pq = None
    if ex.partner is not None:
        partner = sample_at(ex.partner, np.clip(src.reshape(-1), 0, ex.partner.num_frames - 1))
        pr, pq = _normalize(partner, c, n, origin, yaw0)
    body_local = rotate_points_yaw(
        body - np.concatenate((origin[:, None, :1], np.zeros((c, 1, 1)), origin[:, None, 1:]), axis=-1),
        -yaw0[:, None],
    )
    return _ClipMovements(
        root=r,
        rot=q,
        jt=sampled.joint_translations.reshape(c, n, *sampled.joint_translations.shape[1:]),
        partner_root=pr,
        partner_rot=pq,
        end_xz=body_local[:, -1, [0, 2]],
        end_yaw=yaw[:, -1] - yaw0,
        src_clip=np.full(c, ci, dtype=np.intp),
        src_frames=src,
        index_in_clip=np.arange(c, dtype=np.intp),
        regular=spans.max(axis=1) <= MAX_BEAT_RATIO * spans.min(axis=1),
    )


# -- difference measure ----------------------------------------------------------------------------
def _angular_velocity(q: Array, frame: IntArray, fps: float) -> Array:
    """``(M, K, J, 3)`` angular velocity 2 log(q(i-1)^-1 q(i)) * fps (Eq. 1) at frames ``frame (K,)``
    (a forward difference at frame 0)."""
    i1 = np.maximum(frame, 1)
    i0 = i1 - 1
    return 2.0 * rot.log(rot.multiply(rot.conjugate(q[:, i0]), q[:, i1])) * fps


def posture_features(
    mv: Movements, frame: IntArray, yaw_free: bool = False
) -> tuple[Array, Array, Array, Array]:
    """Posture and velocity at movement frames ``frame (K,)``: root position ``(M, K, 3)``, rotations
    ``(M, K, J, 4)``, root velocity ``(M, K, 3)`` m/s and angular velocities ``(M, K, J, 3)`` rad/s.

    ``yaw_free``: express each posture in its own heading frame (root on the Y axis, root rotation
    without the heading) — for comparing the end of one movement with the start of another.
    """
    fps = mv.fps
    p = mv.root[:, frame].copy()
    q = mv.rot[:, frame].copy()
    i1 = np.maximum(frame, 1)
    v = (mv.root[:, i1] - mv.root[:, i1 - 1]) * fps
    if mv.partner_root is not None and mv.partner_rot is not None:
        q = np.concatenate((q, mv.partner_rot[:, frame]), axis=2)
        p = np.concatenate((p, mv.partner_root[:, frame]), axis=-1)
        v = np.concatenate((v, (mv.partner_root[:, i1] - mv.partner_root[:, i1 - 1]) * fps), axis=-1)
    w = _angular_velocity(mv.rot, frame, fps)
    if mv.partner_rot is not None:
        w = np.concatenate((w, _angular_velocity(mv.partner_rot, frame, fps)), axis=2)
    if yaw_free:
        yaw = rot.yaw(mv.rot[:, frame, 0])  # (M, K)
        turn = rot.from_yaw(-yaw)[:, :, None, :]
        q[:, :, 0] = rot.multiply(turn[:, :, 0], q[:, :, 0])
        if mv.partner_rot is not None:
            jn = mv.rot.shape[2]
            q[:, :, jn] = rot.multiply(turn[:, :, 0], q[:, :, jn])
        lead = mv.root[:, frame]
        p3 = p.reshape(*p.shape[:2], -1, 3).copy()
        p3[..., 0] -= lead[..., None, 0]
        p3[..., 2] -= lead[..., None, 2]
        p = rotate_points_yaw(p3, -yaw[..., None]).reshape(p.shape)
        v = rotate_points_yaw(v.reshape(*v.shape[:2], -1, 3), -yaw[..., None]).reshape(v.shape)
    return p, q, v, w


def pairwise_difference(
    a: tuple[Array, Array, Array, Array],
    b: tuple[Array, Array, Array, Array],
    velocity_weight: float,
    chunk: int = 256,
) -> Array:
    """``(Ma, Mb)`` Eq. 12-15 summed over the K frames of the features: ``|p1 - p2|^2 + sum_j
    |log(q1^-1 q2)|^2 + nu (|v1 - v2|^2 + sum_j |w1 - w2|^2)`` (all joint weights 1), computed in
    row chunks so memory stays ``O(chunk * Mb * K * J)``."""
    pa, qa, va, wa = a
    pb, qb, vb, wb = b
    ma, mb = pa.shape[0], pb.shape[0]
    out = np.empty((ma, mb))
    fa = np.concatenate(
        (
            pa.reshape(ma, -1),
            np.sqrt(velocity_weight) * va.reshape(ma, -1),
            np.sqrt(velocity_weight) * wa.reshape(ma, -1),
        ),
        axis=1,
    )
    fb = np.concatenate(
        (
            pb.reshape(mb, -1),
            np.sqrt(velocity_weight) * vb.reshape(mb, -1),
            np.sqrt(velocity_weight) * wb.reshape(mb, -1),
        ),
        axis=1,
    )
    sq = (fa**2).sum(1)[:, None] + (fb**2).sum(1)[None, :] - 2.0 * fa @ fb.T
    qb_t = np.moveaxis(qb, 0, -1)  # (K, J, 4, Mb)
    for s in range(0, ma, chunk):
        e = min(s + chunk, ma)
        dots = np.einsum("mkjc,kjcn->mnkj", qa[s:e], qb_t, optimize=True)
        ang = 2.0 * np.arccos(np.clip(np.abs(dots), 0.0, 1.0))
        out[s:e] = (ang**2).sum(axis=(2, 3))
    return np.asarray(np.maximum(out + sq, 0.0))


def movement_differences(mv: Movements, velocity_weight: float) -> Array:
    """``(M, M)`` difference of movements: Eq. 15, the sum over their ``B + 1`` beat frames."""
    beats = np.arange(mv.beats_per_movement + 1) * mv.frames_per_beat
    f = posture_features(mv, beats)
    d = pairwise_difference(f, f, velocity_weight)
    d = 0.5 * (d + d.T)
    np.fill_diagonal(d, 0.0)
    return d


def transition_differences(mv: Movements, velocity_weight: float) -> Array:
    """``(M, M)`` difference between the last posture of movement i and the first of movement j
    (each in its own heading frame): the kinematic continuity of a transition i -> j."""
    last = posture_features(mv, np.array([mv.frames - 1]), yaw_free=True)
    first = posture_features(mv, np.array([0]), yaw_free=True)
    return pairwise_difference(last, first, velocity_weight)
