"""Resampling a motion to another frame rate (linear positions, slerp rotations)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .errors import MotionError
from .motion import Motion

Array = npt.NDArray[np.float64]


def sample_at(motion: Motion, frames: Array) -> Motion:
    """The motion sampled at fractional frame indices ``frames (N,)`` in ``[0, F-1]``.

    Root positions and animated translations are interpolated linearly, rotations by slerp along
    the shorter arc. The result keeps ``motion.fps``; callers set the rate they mean.
    """
    root, q, jt = sample_arrays_at(motion, frames)
    return replace(motion, root_positions=root, rotations=q, joint_translations=jt)


def checked_frames(motion: Motion, frames: Array) -> Array:
    """``frames`` as a float64 ``(N,)`` array of fractional frame indices of ``motion``; an error
    unless it is non-empty, 1-D and within ``[0, F-1]``."""
    f = np.asarray(frames, dtype=np.float64)
    n = motion.num_frames
    if f.ndim != 1 or f.size == 0:
        raise MotionError("frames must be a non-empty 1-D array of frame indices")
    if not np.all(np.isfinite(f)) or f.min() < 0 or f.max() > n - 1:
        raise MotionError(f"frame indices must lie in [0, {n - 1}]")
    return f


def sample_arrays_at(motion: Motion, frames: Array) -> tuple[Array, Array, Array]:
    """The arrays of :func:`sample_at` without making a motion of them: ``root_positions (N, 3)``,
    ``rotations (N, J, 4)`` and ``joint_translations (N, K, 3)`` at fractional frame indices
    ``frames (N,)`` in ``[0, F-1]`` (for callers that write pieces of several clips into one
    output)."""
    f = checked_frames(motion, frames)
    n = motion.num_frames
    i0 = np.minimum(np.floor(f).astype(np.intp), max(n - 2, 0))
    i1 = np.minimum(i0 + 1, n - 1)
    a = f - i0
    lerp_w = a[:, None]
    root = motion.root_positions[i0] * (1 - lerp_w) + motion.root_positions[i1] * lerp_w
    jt = (
        motion.joint_translations[i0] * (1 - a[:, None, None])
        + motion.joint_translations[i1] * a[:, None, None]
    )
    q = rot.slerp(motion.rotations[i0], motion.rotations[i1], a[:, None])
    return root, q, jt


def resampled_frames(num_frames: int, fps: float, new_fps: float) -> int:
    """Frame count of a ``num_frames`` motion at ``fps`` resampled to ``new_fps`` by :func:`resample`:
    ``floor(duration * new_fps + 1e-9) + 1`` over the same duration (``num_frames`` when the rates
    are equal)."""
    if new_fps == fps:
        return num_frames
    return int(np.floor(max(num_frames - 1, 0) / fps * new_fps + 1e-9)) + 1


def resample(motion: Motion, fps: float) -> Motion:
    """The motion at ``fps`` frames per second over the same duration.

    The new frame count is ``floor(duration * fps + 1e-9) + 1``; frame 0 is unchanged.
    """
    if not (np.isfinite(fps) and 0 < fps <= 10_000):
        raise MotionError(f"fps must be in (0, 10000], got {fps}")
    if fps == motion.fps:
        return motion
    n_new = resampled_frames(motion.num_frames, motion.fps, fps)
    frames = np.minimum(np.arange(n_new) * (motion.fps / fps), motion.num_frames - 1)
    return replace(sample_at(motion, frames), fps=float(fps))
