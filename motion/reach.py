"""Reaching: move end joints (hands) onto per-frame targets with analytic two-bone IK.

For a hand, the chain is shoulder -> elbow -> hand (the nearest distinct ancestors, as the legs of
:mod:`motion.footskate`, whose closed-form two-bone solver this reuses: the elbow bends in its own
plane to the wanted shoulder-hand distance (a nearly straight elbow about the arm's hinge axis,
:func:`motion.footskate.knee_axes`), with soft IK near full extension; the shoulder swings
by the shortest arc; the hand keeps its global orientation). Each target is blended in by a
per-frame weight in ``[0, 1]``: the joint moves to ``position + weight (target - position)``, so a
caller fades corrections in and out. Only the local rotations of the chain's joints change; bone
lengths are preserved. Positions are in the motion's units, Y up.

Three entry points: :func:`reach` (many joints, per-frame targets and weights; the control engine's
hand hold), :func:`reach_path` (one joint moved along by offsets; the rhythm couples' hand hold) and
:func:`reach_at` (one joint onto a point at one frame, faded in and out; the graph engine's shared
meetings, :mod:`engines.graph.coupled`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from .errors import MotionError
from .footskate import Leg, _distinct_ancestor, _forward, _rest_positions, _solve_leg, hinge_axes
from .motion import Motion

Array = npt.NDArray[np.float64]


def smooth_weights(active: npt.NDArray[np.bool_], blend: int) -> Array:
    """``(F,)`` weights: 1 on ``active`` frames, easing (smoothstep) to 0 over ``blend`` frames on
    either side of every run, 0 elsewhere."""
    w = active.astype(np.float64)
    if blend <= 0 or not active.any():
        return w
    idx = np.flatnonzero(active)
    frames = np.arange(active.size)
    # distance (frames) to the nearest active frame
    pos = np.searchsorted(idx, frames)
    left = np.abs(frames - idx[np.clip(pos - 1, 0, idx.size - 1)])
    right = np.abs(idx[np.clip(pos, 0, idx.size - 1)] - frames)
    dist = np.minimum(left, right).astype(np.float64)
    x = np.clip(1.0 - dist / (blend + 1), 0.0, 1.0)
    return np.asarray(x * x * (3.0 - 2.0 * x))


def reach(
    motion: Motion,
    joints: npt.NDArray[np.intp],
    targets: Array,
    weights: Array,
    fk: tuple[Array, Array] | None = None,
) -> Motion:
    """The motion with each of ``joints (K,)`` moved towards ``targets (F, K, 3)`` (motion units)
    by ``weights (F, K)`` (0 = unchanged, 1 = on the target when within reach). ``fk``: the
    motion's :meth:`Motion.fk` when the caller has it already.

    Raises :class:`MotionError` when a joint has no two-bone chain below the root, or two chains
    share joints."""
    n = motion.num_frames
    if targets.shape != (n, joints.size, 3) or weights.shape != (n, joints.size):
        raise MotionError(f"targets must be (F, K, 3) and weights (F, K) for F={n}, K={joints.size}")
    sk = motion.skeleton
    rest = _rest_positions(motion) if fk is None else np.asarray(fk[0][0])
    scale = float(np.abs(sk.offsets[1:]).max(initial=0.0)) or 1.0
    chains: list[Leg] = []
    used: set[int] = set()
    for j in (int(v) for v in joints):
        mid = _distinct_ancestor(sk, rest, j, scale)
        top = _distinct_ancestor(sk, rest, mid, scale) if mid > 0 else -1
        if mid <= 0 or top <= 0:
            raise MotionError(f"no two-bone chain below the root above joint {sk.names[j]!r}")
        members = {top, mid, j}
        if members & used:
            raise MotionError(f"the chain of {sk.names[j]!r} shares joints with another")
        used |= members
        chains.append(Leg(top, mid, j, -1, -1, -1))
    pos, grot = motion.fk() if fk is None else fk
    local = np.array(motion.rotations, copy=True)
    # a straight arm bends with the forearm forward (the opposite of a knee)
    backward = -_forward(motion, pos)
    for k, chain in enumerate(chains):
        frames = np.flatnonzero(weights[:, k] > 0)
        if frames.size == 0:
            continue
        w = weights[frames, k, None]
        target = pos[frames, chain.ankle] + w * (targets[frames, k] - pos[frames, chain.ankle])
        hinge = hinge_axes(chain, pos, grot, backward)[frames]
        _solve_leg(chain, sk, pos, grot, local, frames, target, None, None, hinge)
    return replace(motion, rotations=local)


def reach_path(motion: Motion, joint: int, offsets: Array) -> Motion:
    """``motion`` with joint ``joint`` moved by ``offsets (F, 3)`` metres in every frame (zero rows
    untouched) by arm IK (:func:`reach`); what is beyond the arm's reach is left."""
    offsets = np.asarray(offsets, dtype=np.float64)
    if offsets.shape != (motion.num_frames, 3):
        raise MotionError(f"{offsets.shape[0]} offsets for a motion of {motion.num_frames} frames")
    moving = np.abs(offsets).max(axis=1) > 0
    if not moving.any():
        return motion
    fk = motion.fk()
    targets = fk[0][:, joint] + offsets / motion.metres_per_unit
    return reach(motion, np.array([joint]), targets[:, None], moving[:, None].astype(np.float64), fk)


def reach_at(motion: Motion, joint: int, frame: int, target: Array, window: int) -> tuple[Motion, float]:
    """``motion`` with joint ``joint`` at ``target (3,)`` (metres) at ``frame``: the offset
    ``target - position`` is added to the joint's path with a smoothstep weight, 1 at ``frame``,
    0 at ``window`` frames either side, and each frame is solved by arm IK (:func:`reach`).

    Returns the motion and the distance (metres) left at ``frame`` (beyond the arm's reach).
    Raises :class:`~motion.errors.MotionError` for a frame outside the motion or a joint with no
    two-bone chain above it."""
    n = motion.num_frames
    if not 0 <= frame < n:
        raise MotionError(f"frame {frame} is outside the motion's {n} frames")
    fk = motion.fk()
    mpu = motion.metres_per_unit
    here = fk[0][:, joint]
    delta = np.asarray(target, dtype=np.float64) / mpu - here[frame]
    x = np.clip(1.0 - np.abs(np.arange(n) - frame) / (window + 1.0), 0.0, 1.0)
    weights = (x * x * (3.0 - 2.0 * x))[:, None]
    out = reach(motion, np.array([joint]), (here + delta)[:, None], weights, fk)
    got = out.slice(frame, frame + 1).global_positions()[0, joint]
    return out, float(np.linalg.norm(here[frame] + delta - got)) * mpu
