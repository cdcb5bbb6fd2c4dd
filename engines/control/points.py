"""Point clouds of the control-by-example engine (Hsu et al. 2004, Sec. 3).

Each frame of a control or target motion is a small cloud of joint positions (default: the body root
(hips), the head, both hands and, for targets, both feet: the paper's end effectors plus the trunk;
see :func:`engines.control.build.build_control_database` for why controls leave the feet out). Controls
without a skeleton are clouds too: a walker's control is two floor points, the hips projected on the
floor with a normalised separation (the paper's walk control), built either from a motion's hips or
from a performed path with Frenet frames.

All positions are metres, Y up; clouds are ``(F, P, 3)``.
"""

from __future__ import annotations

import re

import numpy as np
import numpy.typing as npt
from scipy.ndimage import gaussian_filter1d

from motion import Motion
from motion.ground import body_root, facing_pairs, smooth_signal
from motion.mirror import mirror_map
from motion.skeleton import Skeleton

from ..base import EngineError

Array = npt.NDArray[np.float64]

_HAND = re.compile(r"hand|wrist", re.IGNORECASE)
_FOOT = re.compile(r"foot|ankle", re.IGNORECASE)
_HEAD = re.compile(r"head", re.IGNORECASE)
_NOT_HEAD = re.compile(r"end|top|site|eye|nub", re.IGNORECASE)


def default_joints(skeleton: Skeleton, feet: bool = True) -> list[str]:
    """The default point-cloud joints of a skeleton: body root, head, left/right hand and (``feet``)
    left/right foot (each found by name; the shallowest joint of each side wins). Raises
    :class:`EngineError` when no hand (or foot) is found."""
    names = skeleton.names
    depth = skeleton.depth()
    _, side = mirror_map(names)
    chosen = [body_root(skeleton)]
    heads = [j for j in range(len(names)) if _HEAD.search(names[j]) and not _NOT_HEAD.search(names[j])]
    if heads:
        chosen.append(min(heads, key=lambda j: (depth[j], j)))
    for pattern, what in ((_HAND, "hand"), (_FOOT, "foot"))[: 2 if feet else 1]:
        found = False
        for s in (1, -1):
            cands = [j for j in range(len(names)) if side[j] == s and pattern.search(names[j])]
            if cands:
                chosen.append(min(cands, key=lambda j: (depth[j], j)))
                found = True
        if not found:
            raise EngineError(f"no {what} joints found by name; give the point-cloud joints explicitly")
    return [names[j] for j in dict.fromkeys(chosen)]


def joint_indices(skeleton: Skeleton, joints: list[str], what: str) -> npt.NDArray[np.intp]:
    """Indices of named joints; :class:`EngineError` naming the missing ones."""
    missing = [j for j in joints if j not in skeleton.names]
    if missing:
        raise EngineError(
            f"{what}: joints {', '.join(missing)} are not in the skeleton "
            f"(joints: {', '.join(skeleton.names[:12])}...)"
        )
    return np.array([skeleton.names.index(j) for j in joints], dtype=np.intp)


def joint_cloud(motion: Motion, joints: list[str], what: str, positions: Array | None = None) -> Array:
    """``(F, P, 3)`` metres: the named joints' world positions."""
    pos = motion.global_positions() if positions is None else positions
    return np.ascontiguousarray(pos[:, joint_indices(motion.skeleton, joints, what)] * motion.metres_per_unit)


def hips_floor_path(
    motion: Motion, positions: Array | None = None, smooth_s: float = 1.0
) -> tuple[Array, Array]:
    """The hips on the floor: centre ``(F, 2)`` ``[x, z]`` metres and the facing ``(F,)`` radians of the
    hip line, smoothed over ``smooth_s`` seconds (removing the gait's pelvis swing)."""
    pos = motion.global_positions() if positions is None else positions
    pos = pos * motion.metres_per_unit
    pairs = facing_pairs(motion.skeleton)
    if not pairs:
        raise EngineError("cannot derive a walk control: the skeleton has no left/right hip joints")
    left, right = pairs[0]
    centre = 0.5 * (pos[:, left, :] + pos[:, right, :])[:, [0, 2]]
    across = (pos[:, left] - pos[:, right])[:, [0, 2]]
    yaw = np.unwrap(np.arctan2(-across[:, 1], across[:, 0]))
    window = int(round(smooth_s * motion.fps))
    if window > 1 and motion.num_frames > 2:
        yaw = smooth_signal(yaw, window)
    return np.asarray(centre), np.asarray(yaw)


def floor_pair_cloud(centre: Array, yaw: Array, separation_m: float) -> Array:
    """``(F, 2, 3)``: left and right points on the floor, ``separation_m`` apart across the facing
    ``yaw`` (0 = +Z; the left is +X when facing +Z)."""
    left = np.stack((np.cos(yaw), -np.sin(yaw)), axis=-1)  # facing (sin, cos) -> left (cos, -sin)
    half = 0.5 * separation_m * left
    out = np.zeros((centre.shape[0], 2, 3))
    out[:, 0, [0, 2]] = centre + half
    out[:, 1, [0, 2]] = centre - half
    return out


def derived_control(motion: Motion, separation_m: float, positions: Array | None = None) -> Array:
    """The paper's walk control of a motion: hips projected on the floor, normalised separation."""
    centre, yaw = hips_floor_path(motion, positions)
    return floor_pair_cloud(centre, yaw, separation_m)


def trajectory_control(
    points: Array,
    fps: float,
    separation_m: float,
    *,
    spatial_m: float = 0.0,
    temporal_s: float = 0.0,
    max_speed_m_s: float = 4.0,
    speed_window_s: float = 0.5,
) -> tuple[Array, Array]:
    """A performed path as a walk control: Frenet frames along the (optionally smoothed) path.

    Parameters
    ----------
    points:
        ``(F, 2)`` floor positions ``[x, z]`` metres, sampled at ``fps``.
    spatial_m, temporal_s:
        Gaussian smoothing of the path along its arc length (metres) and in time (seconds).
    max_speed_m_s, speed_window_s:
        The path is refused (:class:`EngineError` naming the time span and speed) when its speed over
        any ``speed_window_s`` window exceeds ``max_speed_m_s``.

    Returns
    -------
    cloud:
        ``(F, 2, 3)`` the control point cloud (left/right floor points).
    path:
        ``(F, 2)`` the smoothed path.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 2 or not np.all(np.isfinite(p)):
        raise EngineError("trajectory points must be finite [x, z] pairs, at least 2")
    if temporal_s > 0:
        p = gaussian_filter1d(p, temporal_s * fps, axis=0, mode="nearest")
    if spatial_m > 0:
        p = _smooth_along_arc(p, spatial_m)
    w = max(1, int(round(speed_window_s * fps)))
    if p.shape[0] > w:
        speed = np.linalg.norm(p[w:] - p[:-w], axis=-1) * fps / w
        worst = int(np.argmax(speed))
        if speed[worst] > max_speed_m_s:
            t0, t1 = worst / fps, (worst + w) / fps
            raise EngineError(
                f"the path is too fast between t = {t0:.2f} s and {t1:.2f} s (points {worst}-{worst + w}): "
                f"{speed[worst]:.2f} m/s, more than {max_speed_m_s:g} m/s a walker can do; "
                "perform the path more slowly or smooth it"
            )
    # Frenet frame: tangent from central differences; where the path stops, keep the last direction
    v = np.gradient(p, axis=0)
    speed_f = np.linalg.norm(v, axis=-1)
    moving = speed_f > 1e-4 / fps
    if not moving.any():
        yaw = np.zeros(p.shape[0])
    else:
        yaw_m = np.unwrap(np.arctan2(v[moving, 0], v[moving, 1]))
        idx = np.flatnonzero(moving)
        yaw = np.interp(np.arange(p.shape[0]), idx, yaw_m)
    return floor_pair_cloud(p, yaw, separation_m), p


def _smooth_along_arc(p: Array, sigma_m: float) -> Array:
    """Gaussian smoothing of a path by arc length (frames keep their arc-length position)."""
    seg = np.linalg.norm(np.diff(p, axis=0), axis=-1)
    s = np.concatenate(([0.0], np.cumsum(seg)))
    if s[-1] <= 0:
        return p
    step = max(sigma_m / 4, s[-1] / 100_000)
    grid = np.arange(0.0, s[-1] + step, step)
    # arc length is non-decreasing; np.interp needs strictly increasing abscissae
    keep = np.concatenate(([True], np.diff(s) > 1e-12))
    gx = np.interp(grid, s[keep], p[keep, 0])
    gz = np.interp(grid, s[keep], p[keep, 1])
    sig = sigma_m / step
    gx, gz = gaussian_filter1d(gx, sig, mode="nearest"), gaussian_filter1d(gz, sig, mode="nearest")
    return np.stack((np.interp(s, grid, gx), np.interp(s, grid, gz)), axis=-1)


def resample_cloud(cloud: Array, fps: float, rate: float, frames: int | None = None) -> Array:
    """A cloud ``(F, P, 3)`` at ``fps`` linearly resampled to ``rate``; ``frames`` (default: the same
    duration, ``floor(duration * rate) + 1``) output frames, clamped at the ends."""
    n = cloud.shape[0]
    if frames is None:
        frames = int(np.floor((n - 1) / fps * rate + 1e-9)) + 1
    f = np.minimum(np.arange(frames) * (fps / rate), n - 1)
    return sample_cloud(cloud, f)


def sample_cloud(cloud: Array, frames: Array) -> Array:
    """``cloud (F, ...)`` at fractional frame indices ``frames (...)`` (linear, clamped)."""
    n = cloud.shape[0]
    f = np.clip(np.asarray(frames, dtype=np.float64), 0, n - 1)
    i0 = np.minimum(np.floor(f).astype(np.intp), max(n - 2, 0))
    i1 = np.minimum(i0 + 1, n - 1)
    a = (f - i0).reshape(f.shape + (1,) * (cloud.ndim - 1))
    return np.asarray(cloud[i0] * (1 - a) + cloud[i1] * a)
