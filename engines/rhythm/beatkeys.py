"""Where each basic movement's own beats are, and how clear they are (Kim, Park & Shin 2003, Sec. 5).

The paper time-warps a movement so that its *motion beats* land on the music beats. Movements are
cut and resampled at the examples' motion beats (:mod:`engines.rhythm.movements`), but what the eye
(and the beat-align scores) read as a beat is a dip of the body's speed, and after resampling the
dip of a beat can sit a little before or after the nominal frame ``k P``. So each movement's
*beat keys* are measured on the normalized movement itself:

* ``keys (M, B + 1)`` movement frames: key ``k`` is the deepest local minimum of the summed joint
  speed within ``KEY_WINDOW`` of a beat period around ``k P`` (``k P`` when there is none); the
  first and last keys stay at ``0`` and ``B P`` (the joins between movements);
* ``clarity (M,)`` in [0, 1]: the share of the movement's speed minima (local minima over a sixth
  of a beat either side, as the beat-align score takes them) that fall within ``CLEAR_TOLERANCE``
  of a period of a key, times the share of keys (the end ones included: a movement that does not
  dip where it joins the next one blurs that beat) with a minimum of the speed smoothed over
  ``SMOOTH`` of a period that close (a dip that stays visible): 1 for a movement whose
  speed dips only, and always, on its beats.

Synthesis warps music beat ``k`` onto key ``k`` (a piecewise-linear warp between keys) and prefers
movements with clear beats (:func:`engines.rhythm.synth.plan_movement`). Pure NumPy: these are
per-movement 1-D profiles, nothing a library does better.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

KEY_WINDOW = 0.3
"""A beat key is searched within this fraction of a beat period of the nominal beat frame."""
SMOOTH = 0.12
"""Smoothing (Gaussian, fraction of a beat period) of the speed whose dips count as visible beats."""
CLEAR_TOLERANCE = 0.12
"""A speed minimum within this fraction of a period of a key counts as on the beat."""


def movement_speed(positions: Array) -> Array:
    """``(M, N - 1)`` summed joint speed of movements ``positions (M, N, J, 3)`` (metres per movement
    frame; sample ``i`` is between frames ``i`` and ``i + 1``)."""
    return np.asarray(np.linalg.norm(np.diff(positions, axis=1), axis=-1).sum(axis=-1))


def _local_minima(speed: Array, order: int) -> npt.NDArray[np.bool_]:
    """``(M, S)`` True where a sample is below every other within ``order`` samples (strictly below
    those after it: the last sample of a flat bottom counts)."""
    m, s = speed.shape
    pad = np.pad(speed, ((0, 0), (order, order)), constant_values=np.inf)
    is_min = np.ones((m, s), dtype=bool)
    for d in range(1, order + 1):
        is_min &= speed <= pad[:, order - d : order - d + s]
        is_min &= speed < pad[:, order + d : order + d + s]
    return is_min


def _dips(speed: Array, nominal: Array, p: int) -> Array:
    """``(M, B + 1)``: the deepest local minimum of ``speed (M, S)`` within ``KEY_WINDOW`` of a
    period of each inner nominal beat frame (the nominal frame where there is none, and at the ends)."""
    m, s = speed.shape
    centre = np.arange(s) + 0.5
    keys = nominal.copy()
    near = _local_minima(speed, max(1, int(round(p / 10))))
    for k in range(1, nominal.shape[1] - 1):
        inside = np.abs(centre - nominal[0, k]) <= KEY_WINDOW * p  # (S,)
        cand = np.where(near & inside[None, :], speed, np.inf)
        best = np.argmin(cand, axis=1)
        found = np.isfinite(cand[np.arange(m), best])
        keys[found, k] = centre[best[found]]
    return keys


def beat_keys(speed: Array, frames_per_beat: int, beats_per_movement: int) -> tuple[Array, Array]:
    """Beat keys ``(M, B + 1)`` (movement frames) and clarity ``(M,)`` of movements whose speed
    profiles are ``speed (M, N - 1)`` (module doc)."""
    from scipy.ndimage import gaussian_filter1d

    p, b = frames_per_beat, beats_per_movement
    m, s = speed.shape
    centre = np.arange(s) + 0.5  # movement frame of each speed sample
    nominal = np.broadcast_to(np.arange(b + 1, dtype=np.float64) * p, (m, b + 1))
    smoothed = gaussian_filter1d(speed, SMOOTH * p, axis=1, mode="nearest")
    # the dip of the raw speed and that of the smoothed speed can be a few frames apart (an
    # asymmetric dip): the key is halfway, where both read as being on the beat
    keys = 0.5 * (_dips(speed, nominal, p) + _dips(smoothed, nominal, p))
    tol = CLEAR_TOLERANCE * p
    # precision: the share of the speed's dips (over a sixth of a beat either side) on a key
    minima = _local_minima(speed, max(1, int(round(p / 3))))
    dist = np.abs(centre[None, :, None] - keys[:, None, :]).min(axis=2)  # (M, S) to the nearest key
    n_min = minima.sum(axis=1)
    precision = np.where(n_min > 0, (minima & (dist <= tol)).sum(axis=1) / np.maximum(n_min, 1), 0.0)
    # recall: the share of keys with a dip of the smoothed speed (what stays visible) that close
    smooth = _local_minima(smoothed, 1)
    hit = [(smooth & (np.abs(centre[None, :] - keys[:, k : k + 1]) <= tol)).any(axis=1) for k in range(b + 1)]
    recall = np.mean(np.stack(hit, axis=1), axis=1)
    return keys, np.asarray(precision * recall)


def warp_frames(keys: Array, beat: npt.NDArray[np.intp], x: Array) -> Array:
    """Movement frames ``u (F,)`` at beats ``beat (F,)`` of the movement and warped phases ``x (F,)``
    in [0, 1]: linear between the keys ``(B + 1,)`` of each beat."""
    return np.asarray(keys[beat] + (keys[beat + 1] - keys[beat]) * x)
