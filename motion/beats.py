"""Motion-beat analysis (Kim, Park & Shin 2003, "Rhythmic-Motion Synthesis Based on Motion-Beat Analysis",
section 3): the regular beats of a rhythmic motion (a dance, a walk) found from the motion alone.

The pipeline (vectorized over frames; Python loops run over joint signals or beat events only):

1. **Motion signals** (paper, eq. 1). Per joint the angular velocity of the slerp between consecutive
   frames, ``omega_j(i) = 2 log(q_j(i-1)^-1 q_j(i)) / h`` (rad/s, local joint rotations); with
   ``use_positions=True`` the finite-difference velocity of the world joint positions instead (file
   units/s). Lightly smoothed (Gaussian, ``SMOOTH_S`` seconds). By default only the major joints are
   used (hips, spine, legs, arms, neck, head; not fingers, toes, eyes, twist or helper bones).
2. **Candidate beats** (paper, eq. 2): the zero crossings of every component of the angular
   acceleration, i.e. the extrema of every velocity component, located to sub-frame precision.
   *Choice*: on real capture most raw crossings are noise wiggles (about 300 per joint in 9 s), so each
   carries a salience (its prominence times its width: about the angle swept by the directional
   change, which a uniform time warp leaves unchanged); crossings below ``KEEP_FRACTION`` of their
   joint's typical large salience, and joints that barely move, are dropped.
3. **Dominant period and phase** (paper, eq. 5-8): periodogram of a signal peaking at the candidates,
   sampled at ``4 * fps`` (above Nyquist), inside the tempo prior ``tempo_bpm``; phase = the phase of
   its DTFT at that frequency (the argmax of the correlation with a cosine of that period, eq. 7).
   *Choices*, measured on real walks: (a) the signal is a train of narrow pulses weighted by salience
   rather than the paper's piecewise cosines -- a cosine train's frequency is the local candidate
   *rate*, which follows whichever candidates survive rather than the beat; (b) tempi are ranked by the
   power in a +-``BAND_FRACTION`` relative band, summed with the same for the turn curve of step 4 --
   a motion whose tempo drifts smears each harmonic over a band proportional to its frequency, and the
   raw peak then jumps between the step and the gait-cycle harmonic from one take to the next; (c) the
   tempo doubles while twice it keeps ``HARMONIC_RATIO`` of the power (the beat of a walk is a step).
4. **Beats.** The paper places each beat by a Huber M-estimate of the candidates in
   ``[r_k - T/2, r_k + T/2]`` around the rigid reference grid ``r_k = phase + k T``. Measured on tiled
   walks with every cycle's duration warped by up to +-15% (the paper's make-up protocol), that fails
   twice: the rigid grid drifts off the motion by a whole beat within 30 cycles, and an M-estimate over
   candidates spread across the window moves with whichever candidates enter or leave it (1-4 frames).
   *Choice*: a beat is a moment where the directional changes of the whole body coincide -- a local
   minimum of the radius of curvature of the body's path in configuration space (all joints'
   normalised velocities stacked, see :func:`_turn_curve`), located to sub-frame precision. Curvature
   does not depend on the timing of the path, so the beat stays on the same pose under any time warp.
   A dynamic program (as in Ellis's beat tracker) picks the sequence of minima that maximises their
   depth while keeping consecutive intervals within ``1.25^+-1`` of the dominant period (free) and
   penalising larger departures (``DP_LAMBDA * excess_log_ratio^2``). The reference grid and the
   paper's Huber estimate (solved exactly) remain the fallback when the motion has no such minima.

Accuracy (the paper's make-up protocol: one gait cycle of a Bandai walk tiled 30 times, each cycle's
duration warped by up to +-15%, and the paper's in-cycle jitter; ``bench/beats.py``): see
/work/notes/beats.md for the figures over 24 walks and seeds.

Example
-------
>>> from motion.io import load_motion  # doctest: +SKIP
>>> beats = detect_beats(load_motion("walk.bvh"))  # doctest: +SKIP
>>> round(beats.bpm), beats.frames(30.0)[:3]  # doctest: +SKIP
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.ndimage import gaussian_filter1d, median_filter
from scipy.signal import find_peaks

from . import rotations as rot
from .errors import MotionError
from .motion import Motion

Array = npt.NDArray[np.float64]

SMOOTH_S = 0.025
"""Standard deviation (seconds) of the Gaussian that smooths the velocity signals."""
KEEP_FRACTION = 0.3
"""A candidate is kept when its salience is at least this fraction of its joint's typical large one."""
SCALE_QUANTILE = 0.9
"""Quantile of a joint's candidate saliences taken as its typical large salience."""
FLOOR_FRACTION = 0.1
"""Joints whose typical salience (or mean speed) is below this fraction of the largest are ignored."""
WEIGHT_POWER = 1.0
"""Candidates weigh ``(salience / joint scale, capped at 2) ** WEIGHT_POWER`` in the pulse train."""
SAMPLES_PER_FRAME = 4
"""Periodogram sampling rate in samples per frame (4 * fps > the Nyquist rate 2 * fps)."""
EVENT_SIGMA_S = 0.02
"""Standard deviation (seconds) of the pulse centred on each candidate in the pulse train."""
BAND_FRACTION = 0.1
"""Relative half-width of the frequency band whose power ranks the candidate tempi."""
CURVE_SMOOTH_S = 0.04
"""Standard deviation (seconds) of the Gaussian that smooths the turn (curvature) curve."""
DESPIKE_SAMPLES = 3
"""Running-median length (samples) applied to the velocities of the turn curve: removes one-sample
outliers (a pose jump at a splice or a glitch would read as a sharp turn)."""
HARMONIC_RATIO = 0.5
"""The tempo doubles (a walk's step instead of its gait cycle) while twice it holds this fraction of
the band power ..."""
SLOW_BPM = 88.0
HARMONIC_RATIO_SLOW = 0.2
"""... or this fraction when the tempo is below ``SLOW_BPM`` (slower than any step: a gait cycle or a
bar)."""
DP_RANGE = (0.5, 2.5)
"""Allowed interval between consecutive beats, in dominant periods."""
DP_TOLERANCE = float(np.log(1.25))
"""Intervals within ``period * 1.25^+-1`` cost nothing in the beat tracker."""
DP_LAMBDA = 10.0
"""Cost per squared excess log interval ratio, against minima depths in ``(0, 1]``."""
HUBER_FRACTION = 0.1
"""Huber tuning constant as a fraction of the beat period (rigid-grid fallback)."""
MIN_FRAMES = 8

_MAJOR = re.compile(
    r"hip|pelvis|spine|chest|abdomen|waist|torso|thigh|upleg|upperleg|leg|knee|calf|shin|foot|ankle|"
    r"buttock|collar|clavicle|shoulder|shldr|arm|elbow|hand|wrist|neck|head",
    re.IGNORECASE,
)
_MINOR = re.compile(
    r"finger|thumb|index|pinky|ring|mid|toe|eye|jaw|facial|tongue|teeth|twist|share|nub|end|dummy",
    re.IGNORECASE,
)


@dataclass(frozen=True, slots=True)
class MotionBeats:
    """Motion beats of a clip.

    Attributes
    ----------
    period_s:
        Dominant beat period, seconds.
    phase_s:
        Phase of the reference beats ``r_k = phase_s + k * period_s`` (seconds, ``0 <= phase_s < period_s``).
    times_s:
        ``(B,)`` float64 detected beat times, seconds from frame 0, increasing, inside the clip.
    candidates_s:
        ``(C,)`` float64 candidate beat times (salient zero crossings of the accelerations), seconds,
        increasing.
    """

    period_s: float
    phase_s: float
    times_s: Array
    candidates_s: Array

    @property
    def bpm(self) -> float:
        """Tempo, beats per minute (``60 / period_s``)."""
        return 60.0 / self.period_s

    def frames(self, fps: float) -> Array:
        """``(B,)`` fractional frame indices of the beats at ``fps`` frames per second."""
        if not (np.isfinite(fps) and fps > 0):
            raise MotionError(f"fps must be a positive number, got {fps}")
        return np.asarray(self.times_s * float(fps), dtype=np.float64)


def major_joints(names: Sequence[str]) -> list[int]:
    """Indices of the major body joints by name (hips, spine, legs, arms, neck, head; not fingers, toes,
    eyes, twist or helper bones). Empty when no name matches."""
    return [i for i, n in enumerate(names) if _MAJOR.search(n) and not _MINOR.search(n)]


def _resolve_joints(motion: Motion, joints: Sequence[str | int] | None) -> np.ndarray:
    names = list(motion.skeleton.names)
    j = len(names)
    if joints is None:
        chosen = major_joints(names)
        if not chosen:
            parents = np.asarray(motion.skeleton.parents)
            has_child = np.zeros(j, dtype=bool)
            has_child[parents[parents >= 0]] = True
            chosen = [int(i) for i in np.flatnonzero(has_child)] or list(range(j))
        return np.asarray(chosen, dtype=np.int64)
    if isinstance(joints, str | bytes) or len(joints) == 0:
        raise MotionError("joints must be a non-empty list of joint names or indices")
    out: list[int] = []
    for item in joints:
        if isinstance(item, bool):
            raise MotionError(f"joint {item!r} is neither a name nor an index")
        if isinstance(item, int | np.integer):
            if not 0 <= int(item) < j:
                raise MotionError(f"joint index {item} out of range for a skeleton of {j} joints")
            out.append(int(item))
        elif isinstance(item, str):
            if item not in names:
                raise MotionError(f"unknown joint {item!r}; the skeleton has {', '.join(names[:12])}...")
            out.append(names.index(item))
        else:
            raise MotionError(f"joint {item!r} is neither a name nor an index")
    return np.unique(np.asarray(out, dtype=np.int64))


def _velocity(motion: Motion, joints: np.ndarray, use_positions: bool) -> tuple[Array, float]:
    """Velocity signals ``(F-1, K, 3)`` of the chosen joints; sample ``i`` sits at frame ``i + 0.5``."""
    fps = motion.fps
    if use_positions:
        p = motion.global_positions()[:, joints]
        return np.diff(p, axis=0) * fps, 0.5
    q = rot.normalize(motion.rotations[:, joints])
    rel = rot.multiply(rot.conjugate(q[:-1]), q[1:])
    return 2.0 * rot.log(rel) * fps, 0.5


def _candidates(vel: Array, offset: float, fps: float) -> tuple[Array, Array, Array]:
    """Zero crossings of the acceleration = extrema of the velocity ``vel (N, K, 3)`` (sample ``i`` at
    frame ``i + offset``), with their salience.

    Each extremum of each velocity component is located to sub-frame precision (the zero of the linearly
    interpolated finite-difference acceleration, i.e. the vertex of the parabola through the three
    velocity samples around it). Its salience is its topographic prominence (how far the velocity
    swings back on both sides before exceeding it; small wiggles next to a large swing do not hide it)
    times its width at half prominence: roughly the angle (or distance) swept during the directional
    change, a quantity a uniform time warp leaves unchanged.

    Returns ``(times_s, column, salience)``: seconds, the joint column ``0..K-1``, salience."""
    n, k, _ = vel.shape
    sig = vel.reshape(n, k * 3)
    ts: list[Array] = []
    cs: list[Array] = []
    ss: list[Array] = []
    for c in range(k * 3):
        x = sig[:, c]
        for sign in (1.0, -1.0):
            y = sign * x
            with warnings.catch_warnings():  # flat-topped plateaus have width 0: salience 0, dropped
                warnings.filterwarnings("ignore", message="some peaks have a width of 0")
                peaks, props = find_peaks(y, prominence=0.0, width=0.0, rel_height=0.5)
            if peaks.size == 0:
                continue
            y0, y1, y2 = y[peaks - 1], y[peaks], y[peaks + 1]
            den = y0 - 2.0 * y1 + y2
            shift = np.where(den < 0, 0.5 * (y0 - y2) / np.where(den < 0, den, -1.0), 0.0)
            ts.append((peaks + np.clip(shift, -0.5, 0.5) + offset) / fps)
            cs.append(np.full(peaks.size, c // 3))
            ss.append(props["prominences"] * props["widths"] / fps)
    if not ts:
        return np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0)
    return np.concatenate(ts), np.concatenate(cs).astype(np.int64), np.concatenate(ss)


def _select(joint: np.ndarray, salience: Array, k: int) -> tuple[np.ndarray, Array]:
    """Mask of the salient candidates (``joint (C,)`` columns ``0..k-1``, ``salience (C,)``) and their
    weights ``(C,)``. Each joint's saliences are measured against its own typical large one (their
    ``SCALE_QUANTILE`` quantile), so left and right limbs, big and small joints count alike; a candidate
    is kept when its salience is at least ``KEEP_FRACTION`` of that scale; joints whose scale is below
    ``FLOOR_FRACTION`` of the largest joint's (nearly still) are ignored. Weights = relative salience
    (capped at 2) to the power ``WEIGHT_POWER``."""
    scale = np.zeros(k)
    for j in range(k):
        sj = salience[joint == j]
        if sj.size:
            scale[j] = np.quantile(sj, SCALE_QUANTILE)
    if salience.size == 0 or not np.any(scale > 0):
        return np.zeros(salience.size, dtype=bool), np.zeros(salience.size)
    ok = scale >= FLOOR_FRACTION * scale.max()
    rel = salience / np.where(scale > 0, scale, 1.0)[joint]
    keep = ok[joint] & (rel >= KEEP_FRACTION) & (salience > 0)
    return keep, np.minimum(rel, 2.0) ** WEIGHT_POWER


def _pulse_train(times: Array, weights: Array, grid: Array) -> Array:
    """Sum of Gaussian pulses (standard deviation ``EVENT_SIGMA_S``) of height ``weights`` centred on the
    candidates, sampled at ``grid`` (uniform, seconds)."""
    rate = 1.0 / (grid[1] - grid[0])
    hist = np.zeros(grid.size)
    np.add.at(hist, np.clip(np.rint(times * rate).astype(np.int64), 0, grid.size - 1), weights)
    return np.asarray(gaussian_filter1d(hist, EVENT_SIGMA_S * rate, mode="constant"))


def _dominant(
    signals: Sequence[Array], grid: Array, rate: float, f_lo: float, f_hi: float
) -> tuple[float, float]:
    """Dominant frequency (Hz) inside ``[f_lo, f_hi]`` of the signals (each ``(M,)`` sampled at ``grid``,
    seconds, ``rate`` samples/s) by periodogram, and the phase (s) at which a cosine of that frequency
    correlates best with the first signal (eq. 5-7).

    Each candidate tempo is ranked by the periodogram power within a relative band of
    ``+-BAND_FRACTION`` around it, normalised per signal and summed over the signals: a tempo that
    wanders smears a harmonic over a band proportional to its frequency, so raw peak heights would
    favour the lowest harmonic of a drifting motion, band power does not; two signals (the candidates'
    pulse train and the turn curve) disagree less often on the harmonic than either alone. The peak is
    then refined on a fine DTFT grid of the first signal."""
    m = grid.size
    n = 1 << int(np.ceil(np.log2(max(8 * m, 1024))))
    freqs = np.fft.rfftfreq(n, 1.0 / rate)
    band = np.flatnonzero((freqs >= f_lo) & (freqs <= f_hi))
    if band.size == 0:
        raise MotionError("the tempo range holds no frequency the clip can resolve; widen tempo_bpm")
    f_band = freqs[band]
    lo_i = np.searchsorted(freqs, f_band / (1.0 + BAND_FRACTION), side="left")
    hi_i = np.searchsorted(freqs, f_band * (1.0 + BAND_FRACTION), side="right")
    total = np.zeros(band.size)
    first_spec = np.zeros(freqs.size)
    for k, sig in enumerate(signals):
        x = sig - sig.mean()
        spec = np.abs(np.fft.rfft(x, n)) ** 2 / m
        if k == 0:
            first_spec = spec
        csum = np.concatenate(([0.0], np.cumsum(spec)))
        power = csum[hi_i] - csum[lo_i]
        if power.max() > 0:
            total += power / power.max()
    c = int(np.argmax(total))
    # prefer the finer pulse level (a walk's step over its gait cycle) when it holds comparable power
    while True:
        up = np.flatnonzero(np.abs(f_band - 2.0 * f_band[c]) <= 0.03 * 2.0 * f_band[c])
        if up.size == 0:
            break
        u = up[int(np.argmax(total[up]))]
        ratio = HARMONIC_RATIO if f_band[c] * 60.0 >= SLOW_BPM else HARMONIC_RATIO_SLOW
        if total[u] < ratio * total[c]:
            break
        c = u
    centre = f_band[c]
    near = band[(f_band >= centre / (1.0 + BAND_FRACTION)) & (f_band <= centre * (1.0 + BAND_FRACTION))]
    i = near[int(np.argmax(first_spec[near]))]
    x0 = signals[0] - signals[0].mean()
    df = freqs[1] - freqs[0]
    fine = np.linspace(max(f_lo, freqs[i] - df), min(f_hi, freqs[i] + df), 41)
    dtft = np.exp(-2j * np.pi * np.outer(fine, grid)) @ x0
    j = int(np.argmax(np.abs(dtft)))
    f = float(fine[j])
    phase = float((-np.angle(dtft[j]) / (2.0 * np.pi * f)) % (1.0 / f))
    return f, phase


def _huber(cands: Array, weights: Array, lo: Array, hi: Array, alpha: float, init: Array) -> Array:
    """Weighted Huber M-estimates of the candidates inside each window ``[lo_b, hi_b)`` (exact), or
    ``init_b`` when a window is empty. ``cands`` sorted. Returns ``(B,)`` seconds."""
    start = np.searchsorted(cands, lo, side="left")
    stop = np.searchsorted(cands, hi, side="left")
    count = stop - start
    out = init.copy()
    has = count > 0
    if not np.any(has):
        return out
    width = int(count.max())
    idx = start[:, None] + np.arange(width)[None, :]
    valid = np.arange(width)[None, :] < count[:, None]
    idx = np.where(valid, idx, 0)
    t = cands[idx]
    w = np.where(valid, weights[idx], 0.0)
    # bisection on the monotone estimating equation sum w psi(t - b) = 0
    a = np.where(valid, t, np.inf).min(axis=1)
    b = np.where(valid, t, -np.inf).max(axis=1)
    a = np.where(has, a, init)
    b = np.where(has, b, init)
    for _ in range(60):
        mid = 0.5 * (a + b)
        g = (w * np.clip(t - mid[:, None], -alpha, alpha)).sum(axis=1)
        a = np.where(g > 0, mid, a)
        b = np.where(g > 0, b, mid)
    est = 0.5 * (a + b)
    # exact solution for the final active set (linear region |t - b| < alpha)
    d = t - est[:, None]
    lin = valid & (np.abs(d) < alpha)
    wl = (w * lin).sum(axis=1)
    above = (w * (valid & (d >= alpha))).sum(axis=1)
    below = (w * (valid & (d <= -alpha))).sum(axis=1)
    exact = ((w * lin * t).sum(axis=1) + alpha * (above - below)) / np.where(wl > 0, wl, 1.0)
    est = np.where(wl > 0, exact, est)
    out[has] = est[has]
    return out


def _turn_curve(vel: Array, fps: float, smooth_s: float) -> Array:
    """``(N,)`` minus the log curvature of the whole-body motion path, from the joint velocities
    ``vel (N, K, 3)`` (sample ``i`` of the result at the same time as sample ``i`` of ``vel``).

    Each joint's velocity is divided by its mean speed (so every moving joint counts alike) and the
    joints' velocities are stacked into one ``3K``-vector ``V(t)``, the tangent of the body's path in
    configuration space. The curve is ``log |V| - log |du/dt|`` with ``u = V / |V|``: the log of the
    path's radius of curvature. Its local minima are the sharpest directional changes of the whole body
    (typically where it also slows down): the motion beats. Geometric curvature does not depend on how
    the path is timed, so a beat stays on the same pose when the motion is played faster, slower, or
    with a tempo that changes within a step. Smoothed with a Gaussian of ``smooth_s`` seconds."""
    n = vel.shape[0]
    speed = np.linalg.norm(vel, axis=-1)
    mean = speed.mean(axis=0)
    if mean.size == 0 or mean.max() <= 0 or n < 3:
        return np.zeros(n)
    moving = mean > FLOOR_FRACTION * mean.max()
    v = (vel[:, moving] / mean[moving][None, :, None]).reshape(n, -1)
    norm = np.linalg.norm(v, axis=1)
    tiny = 1e-9 * float(norm.max())
    u = v / np.maximum(norm, tiny)[:, None]
    step = np.linalg.norm(np.diff(u, axis=0), axis=1)  # direction change between samples i and i+1
    turn = np.concatenate((step[:1], 0.5 * (step[1:] + step[:-1]), step[-1:]))
    curve = np.log(np.maximum(norm, tiny)) - np.log(np.maximum(turn, 1e-9 * max(float(turn.max()), 1e-300)))
    if smooth_s * fps >= 0.3:
        curve = gaussian_filter1d(curve, smooth_s * fps, mode="nearest")
    return np.asarray(curve)


def _beat_events(curve: Array, offset: float, fps: float, period: float) -> tuple[Array, Array]:
    """Local minima of ``curve`` (sample ``i`` at frame ``i + offset``): sub-frame times (s, the vertex of
    the parabola through the three samples around each minimum) and strengths in ``(0, 1]`` (depth below
    the curve smoothed over half a beat period, relative to the deepest)."""
    if curve.size < 3:
        return np.zeros(0), np.zeros(0)
    peaks, _ = find_peaks(-curve)
    if peaks.size == 0:
        return np.zeros(0), np.zeros(0)
    y0, y1, y2 = curve[peaks - 1], curve[peaks], curve[peaks + 1]
    den = y0 - 2.0 * y1 + y2
    shift = np.where(den > 0, 0.5 * (y0 - y2) / np.where(den > 0, den, 1.0), 0.0)
    shift = np.clip(shift, -0.5, 0.5)
    envelope = gaussian_filter1d(curve, max(0.5 * period * fps, 1e-3), mode="nearest")
    env = np.interp(peaks + shift, np.arange(curve.size), envelope)
    depth = np.maximum(env - y1, 0.0)
    if depth.max() <= 0:
        return np.zeros(0), np.zeros(0)
    return (peaks + shift + offset) / fps, np.maximum(depth / depth.max(), 1e-6)


def _track(events: Array, strength: Array, period: float, duration: float) -> Array:
    """Tempo-consistent beats among the events (dynamic programming, as in Ellis 2007's beat tracker):
    maximise the summed strength of the chosen events minus, for every interval between consecutive
    beats, ``DP_LAMBDA * max(|log(interval / period)| - DP_TOLERANCE, 0)^2`` (intervals within
    ``DP_RANGE`` periods). A path may only start near the beginning of the clip (or after a gap longer
    than the range), so the chosen beats cover the whole clip. Returns increasing times (s); empty when
    there are no events."""
    e, g = events, strength
    if e.size == 0:
        return np.zeros(0)
    lo = np.searchsorted(e, e - DP_RANGE[1] * period, side="left")
    hi = np.searchsorted(e, e - DP_RANGE[0] * period, side="right")
    start_zone = e < e[0] + DP_RANGE[1] * period
    best = g.copy()
    back = np.full(e.size, -1)
    for m in range(e.size):  # over events (a few per beat), not frames
        if hi[m] > lo[m]:
            prev = slice(lo[m], hi[m])
            dev = np.maximum(np.abs(np.log((e[m] - e[prev]) / period)) - DP_TOLERANCE, 0.0)
            score = best[prev] - DP_LAMBDA * dev**2
            i = int(np.argmax(score))
            if score[i] > 0 or not start_zone[m]:
                best[m] = g[m] + score[i]
                back[m] = lo[m] + i
    m = int(np.argmax(np.where(e >= duration - DP_RANGE[1] * period, best, -np.inf)))
    path = []
    while m >= 0:
        path.append(e[m])
        m = int(back[m])
    return np.asarray(path[::-1], dtype=np.float64)


def detect_beats(
    motion: Motion,
    *,
    joints: Sequence[str | int] | None = None,
    use_positions: bool = False,
    tempo_bpm: tuple[float, float] = (40.0, 200.0),
) -> MotionBeats:
    """Motion beats of ``motion`` (Kim, Park & Shin 2003, sec. 3; see the module docstring).

    Parameters
    ----------
    motion:
        The clip; any frame rate, any skeleton.
    joints:
        Joint names or indices whose signals are analysed; default: the major joints by name (all
        joints with children when no name is recognised).
    use_positions:
        Analyse world joint positions instead of joint orientations.
    tempo_bpm:
        ``(low, high)`` tempo prior in beats per minute: the dominant period is searched in
        ``[60 / high, 60 / low]`` seconds.

    Returns
    -------
    MotionBeats
        Dominant period and phase of the candidates (s), beat times (s from frame 0, increasing, inside
        the clip: the tracked pauses of step 4, or the paper's Huber estimates on the reference grid
        when the motion has none) and the salient candidate times (s). A still motion gets beats on the
        grid of the slowest tempo of the prior.

    Raises
    ------
    MotionError
        For a clip too short to hold two beats of the fastest tempo, an absurd tempo range, or unknown
        joints.
    """
    lo_bpm, hi_bpm = _check_tempo(tempo_bpm, motion.fps)
    _check_length(motion, hi_bpm)
    cols = _resolve_joints(motion, joints)
    vel, offset = _velocity(motion, cols, use_positions)
    return _analyse(vel, offset, motion.fps, (motion.num_frames - 1) / motion.fps, lo_bpm, hi_bpm)


def detect_couple_beats(
    motions: Sequence[Motion],
    *,
    joints: Sequence[str | int] | None = None,
    use_positions: bool = False,
    tempo_bpm: tuple[float, float] = (40.0, 200.0),
) -> MotionBeats:
    """Common motion beats of several synchronized motions (a dancing couple: the paper's waltzing
    couple, "obtained by analyzing their motion signals simultaneously"). The joints of all motions are
    analysed as one body: the same pipeline as :func:`detect_beats` on their stacked velocity signals.

    ``motions`` must share frame rate and frame count (as the CMU salsa partners do); ``joints`` applies
    to each motion. Raises :class:`MotionError` otherwise, or for the same bad input as
    :func:`detect_beats`.
    """
    if len(motions) == 0:
        raise MotionError("detect_couple_beats needs at least one motion")
    fps, frames = motions[0].fps, motions[0].num_frames
    for m in motions[1:]:
        if m.fps != fps or m.num_frames != frames:
            raise MotionError(
                f"synchronized motions must share fps and frame count: {motions[0].name!r} has "
                f"{frames} frames at {fps:g} fps, {m.name!r} has {m.num_frames} at {m.fps:g}"
            )
    lo_bpm, hi_bpm = _check_tempo(tempo_bpm, fps)
    _check_length(motions[0], hi_bpm)
    parts = [_velocity(m, _resolve_joints(m, joints), use_positions) for m in motions]
    vel = np.concatenate([p[0] for p in parts], axis=1)
    return _analyse(vel, parts[0][1], fps, (frames - 1) / fps, lo_bpm, hi_bpm)


def _check_tempo(tempo_bpm: tuple[float, float], fps: float) -> tuple[float, float]:
    try:
        lo_bpm, hi_bpm = (float(v) for v in tempo_bpm)
    except (TypeError, ValueError):
        raise MotionError(f"tempo_bpm must be a (low, high) pair of numbers, got {tempo_bpm!r}") from None
    if not (np.isfinite(lo_bpm) and np.isfinite(hi_bpm) and 0 < lo_bpm < hi_bpm):
        raise MotionError(f"tempo_bpm must be (low, high) with 0 < low < high, got {tempo_bpm}")
    if hi_bpm > 60.0 * fps / 4.0:
        raise MotionError(
            f"tempo_bpm high {hi_bpm:g} is too fast for {fps:g} fps (a beat needs at least 4 frames; "
            f"at most {60.0 * fps / 4.0:g} bpm)"
        )
    return lo_bpm, hi_bpm


def _check_length(motion: Motion, hi_bpm: float) -> None:
    f, fps = motion.num_frames, motion.fps
    duration = (f - 1) / fps
    if f < MIN_FRAMES or duration < 2.0 * 60.0 / hi_bpm:
        raise MotionError(
            f"motion too short for beat analysis: {f} frames ({duration:.2f} s) at {fps:g} fps; "
            f"need at least {MIN_FRAMES} frames and two beats at {hi_bpm:g} bpm ({120.0 / hi_bpm:.2f} s)"
        )


def _analyse(
    vel: Array, offset: float, fps: float, duration: float, lo_bpm: float, hi_bpm: float
) -> MotionBeats:
    """Steps 2-4 of the module docstring on velocity signals ``vel (N, K, 3)`` (sample ``i`` at frame
    ``i + offset``) of a clip of ``duration`` seconds at ``fps``."""
    # one-sample velocity outliers (a pose jump at a splice or a glitch) would read as sharp turns
    curve_vel = (
        median_filter(vel, size=(DESPIKE_SAMPLES, 1, 1), mode="nearest") if DESPIKE_SAMPLES > 1 else vel
    )
    if SMOOTH_S * fps >= 0.3:
        vel = gaussian_filter1d(vel, SMOOTH_S * fps, axis=0, mode="nearest")
        curve_vel = gaussian_filter1d(curve_vel, SMOOTH_S * fps, axis=0, mode="nearest")
    curve = _turn_curve(curve_vel, fps, CURVE_SMOOTH_S)
    times, joint, salience = _candidates(vel, offset, fps)
    keep, weight = _select(joint, salience, vel.shape[1])
    order = np.argsort(times[keep], kind="stable")
    times, weight = times[keep][order], weight[keep][order]

    f_lo = lo_bpm / 60.0
    f_hi = hi_bpm / 60.0
    rate = SAMPLES_PER_FRAME * fps
    grid = np.arange(int(np.floor(duration * rate)) + 1) / rate
    pulses = _pulse_train(times, weight, grid) if times.size else np.zeros(grid.size)
    curve_t = (np.arange(curve.size) + offset) / fps
    if not np.any(pulses > 0) or np.ptp(curve) <= 0:
        # no rhythm at all (a still pose): the slowest tempo of the prior, beats on its grid
        period, phase = 60.0 / lo_bpm, 0.0
    else:
        dips = -np.interp(grid, curve_t, curve)  # peaks where the body pauses, like the pulses
        freq, phase = _dominant([pulses, dips], grid, rate, f_lo, f_hi)
        period = 1.0 / freq
    events, strength = _beat_events(curve, offset, fps, period)
    beats = _track(events, strength, period, duration)
    if beats.size < 2:
        # the paper's estimate on the rigid reference grid r_k = phase + k * period
        k0 = int(np.floor((0.0 - phase) / period)) - 1
        k1 = int(np.ceil((duration - phase) / period)) + 1
        ref = np.asarray(phase + period * np.arange(k0, k1 + 1), dtype=np.float64)
        beats = _huber(times, weight, ref - period / 2, ref + period / 2, HUBER_FRACTION * period, ref)
    beats = np.unique(beats[(beats >= 0.0) & (beats <= duration)])
    # two fallback windows may converge on one cluster: drop beats closer than half a period
    if beats.size > 1:
        keep_b = np.r_[True, np.diff(beats) > 0.5 * period]
        beats = beats[keep_b]
    return MotionBeats(
        period_s=float(period),
        phase_s=float(phase),
        times_s=np.asarray(beats, dtype=np.float64),
        candidates_s=np.asarray(times, dtype=np.float64),
    )
