"""The body-constraint correction as the search sees it: what assembly will do, for whole batches.

Assembly (:mod:`engines.graph.assemble`) meets body constraints, and the floor part of joint
constraints, by spreading the remaining error over the frames before each one
(:func:`motion.floorfit.floor_correction`): a heading ramp that turns the path with the body,
then a position ramp. A path whose end is off by a metre is delivered with its middle moved by
half a metre, perhaps into an obstacle. So that the search scores the motion it will deliver,
:func:`batch_fit` estimates that correction (without the physical limits, which good paths do not
reach) for every path of a batch on a grid of output frames (:class:`FitGrid`): the goal frames
and the obstacle sample frames, every ``step`` frames.

The score then charges each goal for the correction it needs (:attr:`BatchFit.head_inc` and
:attr:`BatchFit.floor_inc`: the heading and position the ramp must add since the previous goal),
and much more for what exceeds what assembly's limits let the frames since the previous goal
absorb (:attr:`BatchFit.head_excess`, :attr:`BatchFit.floor_excess`: estimated from the path's
length and turning, :class:`motion.floorfit.CorrectionLimits`), since that part will not be
delivered; it tests obstacles at the corrected positions (:meth:`BatchFit.corrected`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from motion.floorfit import CorrectionLimits
from motion.rotations import rotate_floor, rotate_floor_by, wrap_angle

from .model import FloatArray, IntArray
from .paths import BatchPieces, GraphIndex, JointTable

FIT_SAMPLES = 48
"""Grid frames over the output (besides goal frames) when no obstacle sets a finer grid."""


@dataclass(frozen=True, slots=True)
class FitGrid:
    """Output frames ``frames (S,)`` (sorted, distinct) the correction is estimated on.

    ``heads``: per heading goal (time order) its grid index, heading (radians), weight and the
    body constraint it comes from; ``floors``: per floor goal (time order) its grid index, the
    body constraint (``kind`` 0, ``ref`` its index in ``Problem.bodies``) or joint constraint
    (``kind`` 1, ``ref`` its index in ``Problem.joints``); ``ramp_lo``, ``ramp_hi``, ``ramp_w``
    ``(S,)``: the floor goals each grid frame's position ramp interpolates between;
    ``samples``: grid indices of the obstacle sample frames."""

    frames: IntArray
    head_at: IntArray
    heading: FloatArray
    head_weight: FloatArray
    floor_at: IntArray
    floor_kind: IntArray
    floor_ref: IntArray
    ramp_lo: IntArray
    ramp_hi: IntArray
    ramp_w: FloatArray
    samples: IntArray
    step: int


def fit_grid(
    length: int,
    bodies: list[tuple[int, FloatArray, float | None, float]],
    joints: list[int],
    obstacle_step: int | None,
) -> FitGrid:
    """The grid of a problem: ``bodies`` ``(frame, xz, heading, weight)`` in time order, the
    frames of the joint constraints (request order), and the obstacle sampling step (or None)."""
    step = obstacle_step or max(1, -(-length // FIT_SAMPLES))
    samples = np.arange(0, length, step, dtype=np.int64)
    goal_frames = [b[0] for b in bodies] + list(joints)
    frames = np.unique(np.concatenate((samples, np.asarray(goal_frames, dtype=np.int64), [length - 1])))
    at = {int(f): i for i, f in enumerate(frames)}
    heads = [(at[f], h, w) for f, _, h, w in bodies if h is not None]
    floors = sorted(
        [(f, 0, i) for i, (f, _, _, _) in enumerate(bodies)] + [(f, 1, i) for i, f in enumerate(joints)]
    )
    floor_frames = np.array([f for f, _, _ in floors], dtype=np.int64)
    s = frames.size
    if floor_frames.size:
        hi = np.clip(np.searchsorted(floor_frames, frames, side="left"), 0, floor_frames.size - 1)
        lo = np.clip(np.searchsorted(floor_frames, frames, side="right") - 1, 0, floor_frames.size - 1)
        span = (floor_frames[hi] - floor_frames[lo]).astype(np.float64)
        w = np.where(span > 0, (frames - floor_frames[lo]) / np.where(span > 0, span, 1.0), 0.0)
        w = np.clip(w, 0.0, 1.0)
    else:
        lo = hi = np.zeros(s, dtype=np.int64)
        w = np.zeros(s)
    return FitGrid(
        frames=frames,
        head_at=np.array([h[0] for h in heads], dtype=np.int64),
        heading=np.array([h[1] for h in heads], dtype=np.float64),
        head_weight=np.array([h[2] for h in heads], dtype=np.float64),
        floor_at=np.array([at[f] for f, _, _ in floors], dtype=np.int64),
        floor_kind=np.array([k for _, k, _ in floors], dtype=np.int64),
        floor_ref=np.array([r for _, _, r in floors], dtype=np.int64),
        ramp_lo=lo.astype(np.int64),
        ramp_hi=hi.astype(np.int64),
        ramp_w=w,
        samples=np.array([at[int(f)] for f in samples], dtype=np.int64),
        step=step,
    )


@dataclass(slots=True)
class BatchFit:
    """The estimated correction of a batch on the grid: for each row and grid frame the source
    ``clip``/``frame`` and piece placement ``th``/``sh`` (uncorrected), the body's uncorrected
    floor position ``xz (B, S, 2)``, the correction angle ``alpha (B, S)`` and the corrected
    body position ``goal (B, S, 2)``; per heading goal the turn the ramp adds since the previous
    one ``head_inc (B, H)`` radians, per floor goal the distance ``floor_inc (B, G)`` metres, and
    the parts of them beyond what the frames since the previous goal can absorb
    (``head_excess``, ``floor_excess``)."""

    clip: IntArray
    frame: IntArray
    th: FloatArray
    sh: FloatArray
    xz: FloatArray
    alpha: FloatArray
    goal: FloatArray
    head_inc: FloatArray
    floor_inc: FloatArray
    head_excess: FloatArray
    floor_excess: FloatArray

    def corrected(self, local: FloatArray, cols: IntArray) -> FloatArray:
        """Corrected world floor positions ``(B, C, K, 2)`` of points given in their clips'
        coordinates ``local (B, C, K, 2)`` (e.g. feet from a :class:`JointTable`) at grid
        columns ``cols (C,)``: ``R(alpha) (R(th) local + sh - xz) + goal``, with floor vectors
        as complex numbers ``x + iz`` (a turn by ``a`` is a product with ``exp(-ia)``)."""
        alpha, th = self.alpha[:, cols], self.th[:, cols]
        turn = np.exp(-1j * alpha)
        offset = turn * _c(self.sh[:, cols] - self.xz[:, cols]) + _c(self.goal[:, cols])
        out = _c(local) * np.exp(-1j * (alpha + th))[..., None] + offset[..., None]
        return np.stack((out.real, out.imag), axis=-1)


def _c(v: FloatArray) -> npt.NDArray[np.complex128]:
    """Floor vectors ``(..., 2)`` as complex numbers ``x + iz``."""
    return np.asarray(v[..., 0] + 1j * v[..., 1])


def _grid_locate(pieces: BatchPieces, frames: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """Piece index, source clip and frame ``(B, S)`` at output ``frames`` (clamped to each path's
    last output frame). The piece index counts the pieces starting at or before each frame, one
    piece column at a time (a batch has a handful of columns and thousands of rows)."""
    total = pieces.count.sum(axis=1)
    tt = np.minimum(frames[None, :], np.maximum(total - 1, 0)[:, None])
    j = np.full(tt.shape, -1, dtype=np.int64)
    for k in range(pieces.start.shape[1]):
        j += pieces.start[:, k, None] <= tt
    j = np.minimum(j, np.maximum((pieces.count > 0).sum(axis=1) - 1, 0)[:, None])
    r = np.arange(pieces.clip.shape[0])[:, None]
    clip = pieces.clip[r, j]
    frame = pieces.first[r, j] + (tt - pieces.start[r, j])
    return j, clip, frame


def batch_fit(
    index: GraphIndex,
    grid: FitGrid,
    pieces: BatchPieces,
    theta: FloatArray,
    shift: FloatArray,
    body_xz: FloatArray,
    joint_xz: FloatArray | None,
    table: JointTable | None,
    joint_columns: IntArray,
    fps: float,
    *,
    with_goal: bool = True,
) -> BatchFit:
    """Estimate the correction of every path of a batch (module docstring).

    ``body_xz (Kb, 2)`` are the body constraints' floor targets (time order); ``joint_xz (Kj, 2)``
    the joint constraints' floor targets and ``joint_columns (Kj,)`` their columns of ``table``.
    Without ``with_goal`` the corrected positions (:attr:`BatchFit.goal`, what obstacles are
    tested at) are left empty ``(B, 0, 2)``: the goals' corrections alone cost less.
    """
    j, clip, frame = _grid_locate(pieces, grid.frames)
    r = np.arange(j.shape[0])[:, None]
    th, sh = theta[r, j], shift[r, j]
    rows = index.tracks.offsets[clip] + frame
    yaw = th + index.tracks.root_yaw[rows]
    # the ground positions turned by each piece's angle (cosines and sines per piece, not per frame)
    cos, sin = np.cos(theta)[r, j], np.sin(theta)[r, j]
    xz = rotate_floor_by(cos, sin, index.root_x[rows], index.root_z[rows]) + sh
    b, s = yaw.shape
    alpha = np.zeros((b, s))
    head_inc = np.zeros((b, grid.head_at.size))
    if grid.head_at.size:
        want = wrap_angle(grid.heading[None, :] - yaw[:, grid.head_at])  # (B, H)
        ks = np.empty_like(want)
        ks[:, 0] = want[:, 0]
        for k in range(1, want.shape[1]):
            head_inc[:, k] = wrap_angle(want[:, k] - ks[:, k - 1])
            ks[:, k] = ks[:, k - 1] + head_inc[:, k]
        at = grid.head_at.astype(np.float64)
        pos = np.arange(s, dtype=np.float64)
        hi = np.clip(np.searchsorted(at, pos, side="left"), 0, at.size - 1)
        lo = np.clip(np.searchsorted(at, pos, side="right") - 1, 0, at.size - 1)
        span = at[hi] - at[lo]
        w = np.clip(np.where(span > 0, (pos - at[lo]) / np.where(span > 0, span, 1.0), 0.0), 0.0, 1.0)
        alpha = ks[:, lo] * (1.0 - w) + ks[:, hi] * w
    # the path with its steps turned by the correction angle, anchored at the first floor goal
    steps = np.diff(xz, axis=1)
    mid = 0.5 * (alpha[:, 1:] + alpha[:, :-1])
    path = np.concatenate((np.zeros((b, 1, 2)), np.cumsum(rotate_floor(mid, steps), axis=1)), axis=1)
    floor_inc = np.zeros((b, grid.floor_at.size))
    floor_excess = np.zeros_like(floor_inc)
    goal = path
    # what the frames between goals can absorb (motion.floorfit's allowances, on the grid)
    limits = CorrectionLimits(np.inf, np.inf)
    seconds = grid.frames.astype(np.float64) / fps
    travelled = np.concatenate((np.zeros((b, 1)), np.cumsum(np.linalg.norm(steps, axis=-1), axis=1)), axis=1)
    turned = np.concatenate((np.zeros((b, 1)), np.cumsum(np.abs(np.diff(yaw, axis=1)), axis=1)), axis=1)
    head_excess = np.zeros_like(head_inc)
    if grid.head_at.size > 1:
        a, z = grid.head_at[:-1], grid.head_at[1:]
        room = limits.turn_fraction * (turned[:, z] - turned[:, a]) + limits.turn_floor * (
            seconds[z] - seconds[a]
        )
        head_excess[:, 1:] = np.maximum(np.abs(head_inc[:, 1:]) - room, 0.0)
    if grid.floor_at.size:
        i0 = int(grid.floor_at[0])
        anchor = (rotate_floor(alpha[:, i0], xz[:, i0]) - path[:, i0])[:, None, :]
        targets = np.empty((b, grid.floor_at.size, 2))
        for g, (at_i, kind, ref) in enumerate(
            zip(grid.floor_at, grid.floor_kind, grid.floor_ref, strict=True)
        ):
            if kind == 0:
                targets[:, g] = body_xz[ref]
            else:
                if table is None or joint_xz is None:  # pragma: no cover - compile_problem builds both
                    raise ValueError("joint floor goals need the joint table")
                p = table.at(clip[:, at_i], frame[:, at_i])[:, joint_columns[ref], :][:, [0, 2]]
                world = rotate_floor(th[:, at_i], p) + sh[:, at_i]
                offset = world - xz[:, at_i]
                targets[:, g] = joint_xz[ref] - rotate_floor(alpha[:, at_i], offset)
        residual = targets - (path[:, grid.floor_at] + anchor)  # (B, G, 2)
        floor_inc[:, 1:] = np.linalg.norm(np.diff(residual, axis=1), axis=-1)
        a, z = grid.floor_at[:-1], grid.floor_at[1:]
        room = limits.speed_fraction * (travelled[:, z] - travelled[:, a])
        room = room + limits.speed_floor * (seconds[z] - seconds[a])
        floor_excess[:, 1:] = np.maximum(floor_inc[:, 1:] - room, 0.0)
        if with_goal:
            ramp = residual[:, grid.ramp_lo] * (1.0 - grid.ramp_w)[None, :, None]
            ramp += residual[:, grid.ramp_hi] * grid.ramp_w[None, :, None]
            goal = (path + anchor) + ramp
    if not with_goal:
        goal = np.zeros((b, 0, 2))
    return BatchFit(clip, frame, th, sh, xz, alpha, goal, head_inc, floor_inc, head_excess, floor_excess)
