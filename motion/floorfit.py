"""Meeting floor goals (body position and heading at given frames) within physical limits.

Arikan & Forsyth 2002 (Sec. 4.2.3) meet body constraints by distributing the remaining error
"uniformly over the portion of the motion before the time of the constraint". Uniform spreading
has no limit: a goal 85 m away drags a walking body at 9 m/s. :func:`floor_correction` spreads
the same residual as evenly as it can *within limits derived from the examples*:

* the corrected body never moves faster than ``limits.speed_max`` nor turns faster than
  ``limits.turn_max`` (the database's fastest example), measured over the
  :data:`motion.plausibility.SPEED_WINDOW_S` window like the quality report;
* the speed added to a frame is at most ``speed_fraction`` (15 %) of the body's own speed there
  plus ``speed_floor`` (5 cm/s): a longer stride, not a slide; likewise for turning (a quarter
  of the frame's own turn rate plus 15 degrees per second).

Per segment between consecutive goals, each frame's allowance is computed and the residual is
water-filled into it (equal shares where the allowances permit, as the paper's uniform spread
would, never above any frame's allowance). Whatever does not fit stays as error: the result
returns it per goal, and the quality report then says the goal is not met.

Headings are corrected first (each frame's step turned by the frame's correction angle, so the
path bends with the body), then positions; before the first goal and after the last one the
correction is rigid (no speed is added). A goal may aim a point other than the body (a joint):
its ``offset`` from the body is turned with the heading correction.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .errors import MotionError
from .plausibility import SPEED_WINDOW_S
from .rotations import rotate_floor, wrap_angle

Array = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class FloorGoal:
    """At output ``frame``: the body's floor point at ``xz (2,)`` metres, and/or its heading at
    ``heading`` radians. With ``offset (2,)`` the goal is for a point that sits ``offset`` from
    the body's floor point in the uncorrected motion (a joint constraint's floor part)."""

    frame: int
    xz: Array | None = None
    heading: float | None = None
    offset: Array | None = None


@dataclass(frozen=True, slots=True)
class CorrectionLimits:
    """How much correction a frame may take (module docstring): speeds m/s, turn rates rad/s."""

    speed_max: float
    turn_max: float
    speed_fraction: float = 0.15
    speed_floor: float = 0.05
    turn_fraction: float = 0.25
    turn_floor: float = float(np.radians(15.0))


@dataclass(frozen=True, slots=True)
class FloorCorrection:
    """Per frame ``theta (F,)`` radians about +Y (about the world origin) then ``shift (F, 2)``
    metres (for :func:`motion.ground.apply_floor_transform`); per goal (input order) the floor
    distance ``position_left (G,)`` metres and heading ``heading_left (G,)`` radians the limits
    did not allow to correct (NaN where the goal sets none)."""

    theta: Array
    shift: Array
    position_left: Array
    heading_left: Array


def water_fill(caps: Array, total: float) -> Array:
    """Shares ``(N,)`` with ``0 <= share <= caps`` adding up to ``min(total, caps.sum())``, as
    equal as the caps allow (the largest minimum share)."""
    caps = np.maximum(np.asarray(caps, dtype=np.float64), 0.0)
    if caps.size == 0 or total <= 0:
        return np.zeros_like(caps)
    if total >= caps.sum():
        return caps.copy()
    c = np.sort(caps)
    n = c.size
    prev = np.concatenate(([0.0], np.cumsum(c)[:-1]))
    reach = prev + (n - np.arange(n)) * c  # the sum at level c[i]: nondecreasing
    i = int(np.searchsorted(reach, total))
    level = (total - prev[i]) / (n - i)
    return np.asarray(np.minimum(caps, level))


def _smoothed_rate(x: Array, fps: float) -> Array:
    """``(F, ...)`` rate of change of ``x (F, ...)`` per second over the speed window (centred,
    one-sided at the ends)."""
    n = x.shape[0]
    w = max(1, int(round(SPEED_WINDOW_S * fps)))
    i = np.arange(n)
    a = np.clip(i - w // 2, 0, n - 1)
    b = np.clip(a + w, 0, n - 1)
    a = np.clip(b - w, 0, n - 1)
    span = np.maximum(b - a, 1).reshape(-1, *([1] * (x.ndim - 1)))
    return np.asarray((x[b] - x[a]) * fps / span)


def floor_correction(
    xz: Array, yaw: Array, fps: float, goals: Sequence[FloorGoal], limits: CorrectionLimits | None
) -> FloorCorrection:
    """The per-frame floor transform meeting ``goals`` as far as ``limits`` allow (module
    docstring); ``limits=None`` spreads without limit (the paper's rule).

    ``xz (F, 2)`` metres and ``yaw (F,)`` radians are the body's floor track
    (:func:`motion.ground.ground_frames`).
    """
    n = xz.shape[0]
    if yaw.shape != (n,) or xz.shape != (n, 2):
        raise MotionError(f"floor track shapes disagree: xz {xz.shape}, yaw {yaw.shape}")
    g = len(goals)
    pos_left = np.full(g, np.nan)
    head_left = np.full(g, np.nan)
    order = sorted(range(g), key=lambda i: goals[i].frame)
    for i in order:
        if not 0 <= goals[i].frame < n:
            raise MotionError(f"floor goal at frame {goals[i].frame} is outside the motion (0..{n - 1})")
    if not goals:
        return FloorCorrection(np.zeros(n), np.zeros((n, 2)), pos_left, head_left)
    alpha = _turn_corrections(yaw, fps, goals, order, limits, head_left)
    path = _turned_path(xz, alpha, goals, order)
    shift = _shift_corrections(path, alpha, fps, goals, order, limits, pos_left)
    return FloorCorrection(alpha, path + shift - rotate_floor(alpha, xz), pos_left, head_left)


def _turn_corrections(
    yaw: Array,
    fps: float,
    goals: Sequence[FloorGoal],
    order: list[int],
    limits: CorrectionLimits | None,
    head_left: Array,
) -> Array:
    """Step 1, headings: ``(F,)`` the correction angle of every frame (radians). The first heading
    goal turns the whole motion rigidly; each later one is reached by turning the frames since the
    previous one within the turn limits. What is left of each goal goes into ``head_left``."""
    n = yaw.shape[0]
    alpha = np.zeros(n)
    omega = _smoothed_rate(yaw, fps) if limits is not None else np.zeros(n)
    prev_t: int | None = None
    for i in (i for i in order if goals[i].heading is not None):
        t = goals[i].frame
        want = float(wrap_angle(float(goals[i].heading) - yaw[t]))  # type: ignore[arg-type]
        if prev_t is None:
            alpha[:] = want  # rigid before (and, until the next goal, after) the first one
            head_left[i] = 0.0
        else:
            need = float(wrap_angle(want - alpha[prev_t]))
            seg = slice(prev_t + 1, t + 1)
            if limits is None:
                steps = np.full(t - prev_t, need / max(t - prev_t, 1))
            else:
                s = np.sign(need)
                w = omega[seg]
                room = np.minimum(
                    limits.turn_fraction * np.abs(w) + limits.turn_floor, limits.turn_max - s * w
                )
                steps = s * water_fill(np.maximum(room, 0.0) / fps, abs(need))
            alpha[seg] = alpha[prev_t] + np.cumsum(steps)
            alpha[t + 1 :] = alpha[t]
            head_left[i] = abs(float(wrap_angle(want - alpha[t])))
        prev_t = t
    return alpha


def _turned_path(xz: Array, alpha: Array, goals: Sequence[FloorGoal], order: list[int]) -> Array:
    """``(F, 2)`` the body's path (metres) with every step turned by its frame's correction, the
    first position goal's frame (else the first goal's) turned about the origin."""
    n = xz.shape[0]
    steps_xz = np.zeros((n, 2))
    steps_xz[1:] = rotate_floor(alpha[1:], np.diff(xz, axis=0))
    path = np.cumsum(steps_xz, axis=0)
    places = [i for i in order if goals[i].xz is not None]
    t0 = goals[places[0] if places else order[0]].frame
    path += rotate_floor(np.array(alpha[t0]), xz[t0]) - path[t0]  # frame t0 turns about the origin
    return np.asarray(path)


def _shift_corrections(
    path: Array,
    alpha: Array,
    fps: float,
    goals: Sequence[FloorGoal],
    order: list[int],
    limits: CorrectionLimits | None,
    pos_left: Array,
) -> Array:
    """Step 2, positions: ``(F, 2)`` the shift of every frame (metres). The first position goal
    places the motion rigidly; each later one is reached by speeding the frames since the
    previous one along the residual within the speed limits. What is left goes into ``pos_left``."""
    n = path.shape[0]
    shift = np.zeros((n, 2))
    velocity = _smoothed_rate(path, fps) if limits is not None else np.zeros((n, 2))
    prev_t: int | None = None
    for i in (i for i in order if goals[i].xz is not None):
        goal = goals[i]
        t = goal.frame
        target = np.asarray(goal.xz, dtype=np.float64)
        if goal.offset is not None:
            target = target - rotate_floor(np.array(alpha[t]), np.asarray(goal.offset, dtype=np.float64))
        residual = target - (path[t] + shift[t])
        dist = float(np.linalg.norm(residual))
        if prev_t is None:
            shift[:] = residual  # rigid: placing the motion costs no speed
            pos_left[i] = 0.0
        elif dist > 0:
            u = residual / dist
            seg = slice(prev_t + 1, t + 1)
            if limits is None:
                share = np.full(t - prev_t, dist / max(t - prev_t, 1))
            else:
                v = velocity[seg]
                along = v @ u
                speed = np.linalg.norm(v, axis=-1)
                # largest a >= 0 with |v + a u| <= speed_max
                disc = along**2 - speed**2 + limits.speed_max**2
                room = np.where(disc > 0, -along + np.sqrt(np.maximum(disc, 0.0)), 0.0)
                room = np.minimum(np.maximum(room, 0.0), limits.speed_fraction * speed + limits.speed_floor)
                share = water_fill(room / fps, dist)
            shift[seg] += np.cumsum(share)[:, None] * u[None, :]
            shift[t + 1 :] = shift[t]
            pos_left[i] = float(np.linalg.norm(target - (path[t] + shift[t])))
        else:
            pos_left[i] = 0.0
        prev_t = t
    return shift


def faded_shifts(frames: npt.NDArray[np.intp], residuals: Array, n: int, half_width: int) -> Array:
    """``(n, 2)`` floor shifts (metres) that are exactly ``residuals (G, 2)`` at ``frames (G,)``
    and fade to zero ``half_width`` frames either side of each: a sum of raised-cosine bumps, their
    amplitudes solved together where bumps overlap (least squares when two goals share a frame).

    Unlike :func:`floor_correction`, nothing moves away from the goals' neighbourhoods: for goals
    that say where a body is at a few moments of a motion placed otherwise (the control engine's
    body placements), not where a whole path goes. The added speed peaks at ``pi / 2`` times the
    residual per ``half_width`` (about 0.8 m/s for 1 m over 2 s); the quality report measures it."""
    if frames.shape[0] != residuals.shape[0] or residuals.shape[1:] != (2,):
        shapes = f"frames {frames.shape}, residuals {residuals.shape}"
        raise MotionError(f"one [x, z] residual per frame: {shapes}")
    if half_width < 1:
        raise MotionError(f"the fade needs at least one frame, got {half_width}")
    if frames.size == 0:
        return np.zeros((n, 2))

    def bumps(at: npt.NDArray[np.intp]) -> Array:
        """``(len(at), G)``: each goal's bump evaluated at frames ``at``."""
        u = np.clip(np.abs(at[:, None] - frames[None, :]) / half_width, 0.0, 1.0)
        return np.asarray(0.5 * (1.0 + np.cos(np.pi * u)))

    amplitudes, *_ = np.linalg.lstsq(bumps(frames), residuals, rcond=None)  # (G, 2)
    return np.asarray(bumps(np.arange(n, dtype=np.intp)) @ amplitudes)
