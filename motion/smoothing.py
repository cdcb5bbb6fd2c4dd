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


def _step_jump(x: Array, d: int) -> Array:
    """Discontinuity of a signal ``(F, ...)`` at frame ``d``: the step across the cut minus the
    mean of the neighbouring steps (one-sided at clip ends)."""
    step = x[d] - x[d - 1]
    neighbours = []
    if d >= 2:
        neighbours.append(x[d - 1] - x[d - 2])
    if d + 1 < x.shape[0]:
        neighbours.append(x[d + 1] - x[d])
    expected = np.mean(neighbours, axis=0) if neighbours else np.zeros_like(step)
    return np.asarray(step - expected)


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
    """
    n = motion.num_frames
    cut_list = sorted({int(c) for c in cuts})
    if any(c < 1 or c > n - 1 for c in cut_list):
        raise MotionError(f"cuts must lie in [1, {n - 1}]")
    root = motion.root_positions.copy()
    jt = motion.joint_translations.copy()
    q = rot.make_continuous(motion.rotations, axis=0)
    for d in cut_list:
        y = displacement_profile(n, d, window, kernel)
        active = np.flatnonzero(y)
        if active.size == 0:
            continue
        root[active] += y[active, None] * _step_jump(root, d)
        if jt.shape[1]:
            jt[active] += y[active, None, None] * _step_jump(jt, d)
        # rotations: the jump is the rotation taking the extrapolated q(d) to the actual one
        pred = rot.multiply(q[d - 1], _relative_step(q, d))
        delta = rot.log(rot.multiply(q[d], rot.conjugate(pred)))  # (J, 3)
        q[active] = rot.multiply(rot.exp(y[active, None, None] * delta[None]), q[active])
    return replace(motion, root_positions=root, rotations=rot.normalize(q), joint_translations=jt)


def _relative_step(q: Array, d: int) -> Array:
    """Typical per-frame rotation step ``(J, 4)`` near ``d`` (mean of the neighbouring steps)."""
    steps = []
    if d >= 2:
        steps.append(rot.log(rot.multiply(rot.conjugate(q[d - 2]), q[d - 1])))
    if d + 1 < q.shape[0]:
        steps.append(rot.log(rot.multiply(rot.conjugate(q[d]), q[d + 1])))
    if not steps:
        return rot.identity(q.shape[1:-1])
    return rot.exp(np.mean(steps, axis=0))
