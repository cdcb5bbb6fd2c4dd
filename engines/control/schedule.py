"""The control engine's anytime schedule, shared by the offline search (:mod:`.engine`) and the
live follower (:mod:`.session`).

A quick narrow beam (width in typical single-segment interpretation costs, at most 16 predecessors
x 128 successors per boundary), a wider beam (width in the quick solution's mean cost per segment,
64 x 256 cells: the exact optimum on all 14 leave-one-out salsa dances), then the exact optimum
(branch and bound).
"""

from __future__ import annotations

QUICK_WIDTH = 3.0
QUICK_CELLS = (16, 128)
BEAM_WIDTH = 10.0
BEAM_CELLS = (64, 256)
