"""Quality metrics of a motion, in metres and seconds.

* :func:`foot_slip` — mean horizontal speed of feet while in contact (m/s; 0 is ideal).
* :func:`jerk` — mean magnitude of the third time derivative of joint positions (m/s^3);
  :func:`points_jerk` the same for any point array.
* :func:`cut_discontinuity` — at each cut, how far the step across the cut departs from the
  neighbouring steps (m), the largest over joints.
* :func:`beat_align_scores` — how well a motion's beats land on music beats (the AIST++ "mint"
  and Bailando conventions).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .contacts import detect_contacts
from .errors import MotionError
from .motion import Motion
from .vectors import norms

Array = npt.NDArray[np.float64]


def foot_slip(
    motion: Motion,
    positions: Array | None = None,
    contacts: npt.NDArray[np.bool_] | None = None,
    joints: npt.NDArray[np.intp] | None = None,
) -> float:
    """Mean horizontal foot speed over contact frames, m/s (0 when no contact is found).

    Contacts default to :func:`motion.contacts.detect_contacts`; pass ``joints`` and ``contacts``
    (``(F, K)``) to score given contacts, e.g. those propagated by an engine.
    """
    pos = motion.global_positions() if positions is None else positions
    if contacts is None:
        joints, contacts = detect_contacts(motion, joints, positions=pos)
    elif joints is None:
        raise MotionError("pass the joints the contacts refer to")
    if motion.num_frames < 2:
        return 0.0
    feet = pos[:, joints][:, :, [0, 2]] * motion.metres_per_unit
    speed = np.linalg.norm(np.diff(feet, axis=0), axis=-1) * motion.fps  # (F-1, K)
    both = contacts[1:] & contacts[:-1]
    return float(speed[both].mean()) if both.any() else 0.0


def jerk(motion: Motion, positions: Array | None = None) -> float:
    """Mean magnitude of the third derivative of all joint positions, m/s^3."""
    pos = (motion.global_positions() if positions is None else positions) * motion.metres_per_unit
    return points_jerk(pos, motion.fps)


def points_jerk(points: Array, fps: float) -> float:
    """Mean magnitude of the third time derivative of ``points (F, ..., 3)`` metres sampled at
    ``fps``, m/s^3 (0 with fewer than 4 frames)."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape[0] < 4:
        return 0.0
    third = np.diff(p, n=3, axis=0) * fps**3
    return float(norms(third).mean())


def cut_discontinuity(
    motion: Motion, cuts: list[int] | npt.NDArray[np.intp], positions: Array | None = None
) -> Array:
    """``(len(cuts),)`` metres: at each cut ``d``, ``max_j || (x_d - x_{d-1}) - mean(neighbour steps) ||``.

    A seamless cut scores about the frame-to-frame change of velocity (millimetres at 30+ fps).
    """
    pos = (motion.global_positions() if positions is None else positions) * motion.metres_per_unit
    n = motion.num_frames
    out = []
    for d in cuts:
        d = int(d)
        if not 1 <= d <= n - 1:
            raise MotionError(f"cut {d} outside [1, {n - 1}]")
        step = pos[d] - pos[d - 1]
        neighbours = [pos[d - 1] - pos[d - 2]] if d >= 2 else []
        if d + 1 < n:
            neighbours.append(pos[d + 1] - pos[d])
        expected = np.mean(neighbours, axis=0) if neighbours else np.zeros_like(step)
        out.append(float(np.linalg.norm(step - expected, axis=-1).max()))
    return np.array(out)


def beat_align_scores(
    positions: Array, fps: float, music_s: Array, sigma_s: float = 0.05
) -> tuple[float, float, Array]:
    """Beat-align scores of ``positions (F, J, 3)`` (metres) against music beats (seconds).

    Motion beats are local minima of the summed joint speed. AIST++/mint: for every motion beat
    (minimum within +-1/6 s), ``exp(-d^2 / 2 sigma^2)`` of the distance to the nearest music beat,
    averaged; Bailando: for every inner music beat, the same of the distance to the nearest minimum
    of the speed smoothed by a 5-frames-at-60-fps Gaussian. Returns (mint, bailando, motion beats s).
    """
    from scipy.ndimage import gaussian_filter1d  # imported here: scipy.signal takes ~0.7 s to import
    from scipy.signal import argrelextrema

    music = np.asarray(music_s, dtype=np.float64)
    if positions.shape[0] < 5 or music.size == 0:
        return 0.0, 0.0, np.zeros(0)
    speed = np.linalg.norm(np.diff(positions, axis=0), axis=-1).sum(axis=1) * fps
    mb = argrelextrema(speed, np.less, order=max(1, int(round(10 / 60 * fps))))[0] / fps
    if mb.size:
        d = _nearest_distance(mb, music)
        mint = float(np.mean(np.exp(-(d**2) / (2 * sigma_s**2))))
    else:
        mint = 0.0
    mb2 = argrelextrema(gaussian_filter1d(speed, 5 / 60 * fps), np.less)[0] / fps
    inner = music[1:-1]
    if mb2.size and inner.size:
        d2 = _nearest_distance(inner, mb2)
        bail = float(np.mean(np.exp(-(d2**2) / (2 * sigma_s**2))))
    else:
        bail = 0.0
    return mint, bail, np.asarray(mb, dtype=np.float64)


def _nearest_distance(x: Array, ref: Array) -> Array:
    """``(N,)`` distance from each of ``x (N,)`` to the nearest of ``ref (M,)`` (any order)."""
    r = np.sort(ref)
    i = np.clip(np.searchsorted(r, x), 1, max(r.size - 1, 1))
    lo = r[np.minimum(i - 1, r.size - 1)]
    hi = r[np.minimum(i, r.size - 1)]
    return np.asarray(np.minimum(np.abs(x - lo), np.abs(x - hi)))
