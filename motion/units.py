"""Length units: the table of known units, standing height and a guess of a file's unit.

BVH files do not declare their unit. Segue estimates the standing height in the file's own unit
and picks the known unit that makes it closest to an adult's height (1.7 m); the guess is only a
default: callers can declare the unit instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

METRES_PER_UNIT: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "in": 0.0254,
    "ft": 0.3048,
    "cmu": 0.0254 / 0.45,  # CMU ASF length unit (1/0.45 inch), kept by many CMU BVH conversions
    "cmu-scaled": 1.28,  # CMU "_scaled" BVH conversions (cmu-salsa): the CMU-Daz figure's cm / 128
}
GUESSED_UNITS = ("m", "cm", "mm", "in", "ft", "cmu")
"""The units :func:`guess_units` chooses among. ``cmu-scaled`` (1.28 m) is only 28 % away from the
metre, too close to tell apart by height, so it must be declared: the CMU salsa "scaled" files
(``cmu-salsa/*_scaled.bvh``) hold the 43-joint CMU-Daz figure (the one of ``cmu-daz/``, in
centimetres: its hips fall at 9.1-9.7 m/s^2 in the jump clips) with every offset divided by 128,
so one of their units is 1.28 m and their dancers stand 1.46 m to the eyes, like the Daz walkers,
not 1.14 m."""
TYPICAL_HEIGHT_M = 1.7
PLAUSIBLE_HEIGHT_M = (0.9, 2.4)


@dataclass(frozen=True, slots=True)
class UnitGuess:
    """Result of :func:`guess_units`.

    Attributes
    ----------
    units: the best unit name (a key of :data:`METRES_PER_UNIT`).
    height: standing height in the file's unit.
    height_m: that height in metres under the guessed unit.
    plausible: whether ``height_m`` lies in :data:`PLAUSIBLE_HEIGHT_M`.
    """

    units: str
    height: float
    height_m: float
    plausible: bool


UP_AXIS_RATIO = 1.2
""":func:`up_axis` says Z when the points' median extent along Z is this many times that along Y."""


def up_axis(frame_points: npt.NDArray[np.float64]) -> int:
    """The vertical axis of a motion's points ``(F, P, 3)``: 1 (Y, the BVH custom and Segue's frame)
    or 2 (Z, e.g. Unreal's convention), from the median over frames of each axis' extent: a body
    is taller than it is wide or deep, so Z is up when its extent is ``UP_AXIS_RATIO`` times Y's
    (a clip that never stands, e.g. crawling in a Y-up file, can fool it: declare it then)."""
    fp = np.asarray(frame_points)
    if fp.size == 0:
        return 1
    ext = np.median(fp.max(axis=-2) - fp.min(axis=-2), axis=0)  # (3,)
    return 2 if ext[2] > UP_AXIS_RATIO * ext[1] else 1


def standing_height(frame_points: npt.NDArray[np.float64], axis: int = 1) -> float:
    """Standing height in the points' unit: the median over frames of the vertical extent.

    Parameters
    ----------
    frame_points:
        ``(F, P, 3)`` joint and End Site positions over a motion, ``axis`` up (1: Y, 2: Z).

    Rest poses are not used: many files (e.g. Bandai-Namco) define them lying down. The median
    is robust to a few crouching, jumping or arms-up frames; a clip that never stands upright
    (crawling) under-reports, and callers can declare units instead.
    """
    fp = np.asarray(frame_points)
    if fp.size == 0:
        return 0.0
    per_frame = fp[..., axis].max(axis=-1) - fp[..., axis].min(axis=-1)
    return float(np.median(per_frame))


def guess_units(height: float) -> UnitGuess:
    """The unit of :data:`GUESSED_UNITS` that makes ``height`` (file units) closest to 1.7 m, on a
    log scale."""
    if not (height > 0 and math.isfinite(height)):
        return UnitGuess("m", float(height), float(height), False)
    best = min(GUESSED_UNITS, key=lambda u: abs(math.log(height * METRES_PER_UNIT[u] / TYPICAL_HEIGHT_M)))
    h_m = height * METRES_PER_UNIT[best]
    lo, hi = PLAUSIBLE_HEIGHT_M
    return UnitGuess(best, float(height), float(h_m), lo <= h_m <= hi)
