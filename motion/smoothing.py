"""Hiding the discontinuities at cuts between concatenated motion pieces.

:func:`smooth_cuts` applies the displacement smoothing of Arikan & Forsyth 2002 (Sec. 4.2.3): the
jump at a cut is measured, and a smooth displacement that reaches +1/2 of it just before the cut
and -1/2 just after, and fades to zero ``window`` frames away, is added to the signal (root
position and every joint rotation). ``kernel="linear"`` uses straight ramps instead of the
paper's C1 quadratic ones.

The jump is measured against the local velocity (``x(d) - x(d-1)`` minus the mean of the steps on
either side), so the motion's own progress across the cut is kept and only the discontinuity is
spread; the paper leaves this choice open.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Literal

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .errors import MotionError
from .motion import Motion

Array = npt.NDArray[np.float64]
Kernel = Literal["arikan", "linear"]


def displacement_profile(n_frames: int, cut: int, window: int, kernel: Kernel = "arikan") -> Array:
    """``(F,)`` the weight y(f) of the jump added at each frame for a cut at frame ``cut``.

    ``arikan`` (the paper's y(f), with u = (f - d + s) / s): ``u^2 / 2`` for ``d - s <= f < d``,
    ``-u^2 / 2 + 2u - 2`` for ``d <= f <= d + s``, 0 elsewhere; ``linear``: ``u / 2`` before and
    ``(u - 2) / 2`` after.
    """
    if window < 1:
        raise MotionError(f"smoothing window must be at least 1 frame, got {window}")
    f = np.arange(n_frames, dtype=np.float64)
    u = (f - cut + window) / window
    y = np.zeros(n_frames)
    before = (f >= cut - window) & (f < cut)
    after = (f >= cut) & (f <= cut + window)
    if kernel == "arikan":
        y[before] = 0.5 * u[before] ** 2
        y[after] = -0.5 * u[after] ** 2 + 2.0 * u[after] - 2.0
    elif kernel == "linear":
        y[before] = 0.5 * u[before]
        y[after] = 0.5 * (u[after] - 2.0)
    else:
        raise MotionError(f"unknown smoothing kernel {kernel!r}; use 'arikan' or 'linear'")
    return y


def _step_jumps(x: Array, d: npt.NDArray[np.intp]) -> Array:
    """Discontinuities ``(B, ...)`` of a signal ``x (F, ...)`` at frames ``d (B,)``: the step across
    each cut minus the mean of the neighbouring steps (one-sided at clip ends)."""
    n = x.shape[0]
    step = x[d] - x[d - 1]
    before, after = d >= 2, d + 1 < n
    shape = (-1,) + (1,) * (x.ndim - 1)
    prev = x[d - 1] - x[np.maximum(d - 2, 0)]
    nxt = x[np.minimum(d + 1, n - 1)] - x[d]
    total = np.where(before.reshape(shape), prev, 0.0) + np.where(after.reshape(shape), nxt, 0.0)
    count = (before.astype(np.float64) + after).reshape(shape)
    expected = np.where(count > 0, total / np.maximum(count, 1.0), 0.0)
    return np.asarray(step - expected)


def independent_batches(cuts: list[int], window: int) -> list[list[int]]:
    """Sorted ``cuts`` in runs that :func:`smooth_cuts` may treat at once: within a run, no cut's
    displacement (frames ``c - window + 1 .. c + window - 1``) reaches the four frames the next
    cut's jump is measured on (``d - 2 .. d + 1``) or that cut's own displacement, so measuring
    every jump of the run first and then adding every displacement gives what one cut after
    the other does."""
    batches: list[list[int]] = []
    for d in cuts:
        if batches and batches[-1][-1] + window - 1 < min(d - 2, d - window + 1):
            batches[-1].append(d)
        else:
            batches.append([d])
    return batches


def smooth_cuts(
    motion: Motion, cuts: list[int] | npt.NDArray[np.intp], window: int, kernel: Kernel = "arikan"
) -> Motion:
    """The motion with the discontinuity at each cut spread over ``+-window`` frames.

    Parameters
    ----------
    motion:
        A motion assembled from pieces; ``cuts`` are the first frames of the later pieces.
    cuts:
        Frame indices in ``[1, F-1]``.
    window:
        Half-width ``s`` of the smoothing domain in frames (the paper uses 30 at 30 fps).
    kernel:
        ``"arikan"`` (C1 quadratic, the paper's) or ``"linear"``.

    Cuts are smoothed one after the other (a cut's jump is measured after the displacements of
    the cuts before it); cuts far enough apart not to touch each other's frames are done together
    (:func:`independent_batches`), which gives the same result.
    """
    n = motion.num_frames
    cut_list = sorted({int(c) for c in cuts})
    if any(c < 1 or c > n - 1 for c in cut_list):
        raise MotionError(f"cuts must lie in [1, {n - 1}]")
    root = motion.root_positions.copy()
    jt = motion.joint_translations.copy()
    q = rot.make_continuous(motion.rotations, axis=0)
    if cut_list:
        displacement_profile(1, 0, window, kernel)  # the window's and the kernel's checks
    for batch in independent_batches(cut_list, window):
        d = np.array(batch, dtype=np.intp)
        frames, weight, owner = _displaced_frames(d, n, window, kernel)
        if frames.size == 0:
            continue
        root[frames] += weight[:, None] * _step_jumps(root, d)[owner]
        if jt.shape[1]:
            jt[frames] += weight[:, None, None] * _step_jumps(jt, d)[owner]
        # rotations: the jump is the rotation taking the extrapolated q(d) to the actual one
        pred = rot.multiply(q[d - 1], _relative_steps(q, d))
        delta = rot.log(rot.multiply(q[d], rot.conjugate(pred)))  # (B, J, 3)
        q[frames] = rot.multiply(rot.exp(weight[:, None, None] * delta[owner]), q[frames])
    return replace(motion, root_positions=root, rotations=rot.normalize(q), joint_translations=jt)


def _displaced_frames(
    d: npt.NDArray[np.intp], n_frames: int, window: int, kernel: Kernel
) -> tuple[npt.NDArray[np.intp], Array, npt.NDArray[np.intp]]:
    """The frames a batch of cuts ``d (B,)`` displaces (where :func:`displacement_profile` is not
    zero), their weights and the index in ``d`` of the cut displacing each."""
    offsets = np.arange(-window, window + 1)
    f = d[:, None] + offsets[None, :]  # (B, 2 window + 1)
    inside = (f >= 0) & (f < n_frames)
    u = (f.astype(np.float64) - d[:, None] + window) / window
    before = offsets[None, :] < 0
    if kernel == "arikan":
        y = np.where(before, 0.5 * u**2, -0.5 * u**2 + 2.0 * u - 2.0)
    else:
        y = np.where(before, 0.5 * u, 0.5 * (u - 2.0))
    keep = inside & (y != 0)
    owner = np.broadcast_to(np.arange(d.size)[:, None], f.shape)[keep]
    return f[keep], y[keep], owner


def _relative_steps(q: Array, d: npt.NDArray[np.intp]) -> Array:
    """Typical per-frame rotation steps ``(B, J, 4)`` near frames ``d (B,)`` (the mean of the
    neighbouring steps' rotation vectors; the identity at a one-frame motion)."""
    n = q.shape[0]
    before, after = d >= 2, d + 1 < n
    prev = rot.log(rot.multiply(rot.conjugate(q[np.maximum(d - 2, 0)]), q[d - 1]))
    nxt = rot.log(rot.multiply(rot.conjugate(q[d]), q[np.minimum(d + 1, n - 1)]))
    total = np.where(before[:, None, None], prev, 0.0) + np.where(after[:, None, None], nxt, 0.0)
    count = (before.astype(np.float64) + after)[:, None, None]
    return rot.exp(np.where(count > 0, total / np.maximum(count, 1.0), 0.0))
