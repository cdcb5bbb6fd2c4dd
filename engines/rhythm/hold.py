"""Couples' hand hold, tightened (request ``hand_hold.reach``).

The follower is blended with the leader's movements in the leader's frame, so the pair's hands
are about as close as in the example couples, which hold hands loosely or let go. Where the two
hands are near (closer than :data:`NEAR` times the hold distance) but not within it, both hands
are brought towards each other by arm IK (:func:`motion.reach.reach_path`), each half the way
to :data:`SNUG` of the hold distance, at most :data:`MAX_REACH_M` per hand. Where they are apart
(a let-go, a turn), nothing changes. The amount is faded over :data:`FADE_S` (a Hann-weighted
moving average of the "near" flag), so a hold does not snap on or off; the quality report is
measured on the result.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from motion import Motion
from motion.reach import reach_path

Array = npt.NDArray[np.float64]

NEAR = 2.0
"""Hands closer than this many hold distances are brought together."""
SNUG = 0.8
"""Where a held pair of hands is brought: this fraction of the hold distance."""
MAX_REACH_M = 0.3
"""Largest move of one hand, metres."""
FADE_S = 0.5
"""Seconds over which a hold fades in and out."""


def hold_hands(
    lead: Motion, follow: Motion, lead_joint: int, follow_joint: int, max_m: float
) -> tuple[Motion, Motion]:
    """The couple with the two hands brought together where they are near (module docstring);
    both motions in metres, of one length and rate."""
    pl = lead.global_positions()[:, lead_joint] * lead.metres_per_unit
    pf = follow.global_positions()[:, follow_joint] * follow.metres_per_unit
    gap = pf - pl
    d = np.linalg.norm(gap, axis=1)
    near = (d < NEAR * max_m).astype(np.float64)
    half = max(1, int(round(FADE_S * lead.fps / 2)))
    win = np.hanning(2 * half + 3)[1:-1]
    w = np.convolve(near, win / win.sum(), mode="same") * near
    close = w * np.maximum(d - SNUG * max_m, 0.0) / 2  # metres each hand moves
    close = np.minimum(close, MAX_REACH_M)
    step = gap / np.maximum(d, 1e-9)[:, None] * close[:, None]
    return reach_path(lead, lead_joint, step), reach_path(follow, follow_joint, -step)
