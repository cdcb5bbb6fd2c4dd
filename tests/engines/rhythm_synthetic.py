"""A tiny synthetic dancer with known motion beats, for the rhythm engine's tests.

A 17-joint figure (CMU-like names) whose arms and legs swing back and forth: every swing reverses
exactly at the beat times (angular velocity zero, angular acceleration at its extreme), so the
beats are known without beat analysis. Clips differ in tempo, amplitude and drift so that time
normalization, clustering and blending have something to do.
"""

from __future__ import annotations

import numpy as np

from engines.library import MotionLibrary
from motion import Motion, Skeleton
from motion import rotations as rot
from motion.skeleton import default_channels

NAMES = (
    "hip", "abdomen", "chest", "neck", "head",
    "lShldr", "lForeArm", "lHand", "rShldr", "rForeArm", "rHand",
    "lThigh", "lShin", "lFoot", "rThigh", "rShin", "rFoot",
)  # fmt: skip
PARENTS = np.array([-1, 0, 1, 2, 3, 2, 5, 6, 2, 8, 9, 0, 11, 12, 0, 14, 15])
OFFSETS = np.array(
    [
        [0, 0.95, 0], [0, 0.1, 0], [0, 0.2, 0], [0, 0.2, 0], [0, 0.1, 0],
        [0.18, 0.15, 0], [0.28, 0, 0], [0.25, 0, 0], [-0.18, 0.15, 0], [-0.28, 0, 0], [-0.25, 0, 0],
        [0.1, -0.05, 0], [0, -0.42, 0], [0, -0.42, 0], [-0.1, -0.05, 0], [0, -0.42, 0], [0, -0.42, 0],
    ],
    dtype=np.float64,
)  # fmt: skip


def skeleton() -> Skeleton:
    return Skeleton(
        NAMES,
        PARENTS,
        OFFSETS,
        default_channels(len(NAMES)),
        np.array([4, 7, 10, 13, 16]),
        np.full((5, 3), 0.05),
    )


def swing_phase(t: np.ndarray, beats: np.ndarray) -> np.ndarray:
    """``cos(pi * (k + x))`` with ``x`` the fraction of beat ``k`` elapsed at ``t``: +-1 at the beats
    (direction reversal), smooth in between."""
    k = np.clip(np.searchsorted(beats, t, side="right") - 1, 0, beats.size - 2)
    x = np.clip((t - beats[k]) / (beats[k + 1] - beats[k]), 0.0, 1.0)
    return np.asarray(np.cos(np.pi * (k + x)))


def dancer(
    beats: np.ndarray, fps: float = 30.0, amplitude: float = 0.6, drift: float = 0.0, name: str = "d"
) -> Motion:
    """A motion whose limbs reverse direction at ``beats`` (seconds); ``drift`` m/s forward travel."""
    t = np.arange(int(np.floor(beats[-1] * fps)) + 1) / fps
    s = swing_phase(t, beats)
    f = t.size
    q = rot.identity((f, len(NAMES)))
    x_axis = np.array([1.0, 0.0, 0.0])
    z_axis = np.array([0.0, 0.0, 1.0])
    for j, sign in ((5, 1), (8, -1)):  # arms swing up/down
        q[:, j] = rot.from_axis_angle(z_axis, sign * amplitude * s)
    for j, sign in ((11, 1), (14, -1)):  # legs swing forward/back
        q[:, j] = rot.from_axis_angle(x_axis, sign * 0.5 * amplitude * s)
    q[:, 1] = rot.from_axis_angle(np.array([0.0, 1.0, 0.0]), 0.2 * amplitude * s)
    root = np.zeros((f, 3))
    root[:, 1] = 0.95
    root[:, 2] = drift * t
    return Motion(skeleton(), root, q, fps, np.zeros((f, 0, 3)), "m", name)


def library(
    count: int = 3, fps: float = 30.0, seconds: float = 12.0
) -> tuple[MotionLibrary, dict[str, list[float]]]:
    """``count`` dancers at different tempi (0.5 s to 0.6 s beats, jittered) and their beats."""
    rng = np.random.default_rng(7)
    motions, beats = [], {}
    for i in range(count):
        period = 0.5 + 0.05 * i
        n = int(seconds / period)
        b = np.cumsum(np.concatenate(([0.2], period * (1 + 0.08 * rng.uniform(-1, 1, n)))))
        name = f"dance{i}"
        motions.append(dancer(b, fps, amplitude=0.4 + 0.15 * i, drift=0.1 * i, name=name))
        beats[name] = [float(x) for x in b]
    return MotionLibrary(tuple(m.name for m in motions), tuple(motions), tuple(() for _ in motions)), beats
