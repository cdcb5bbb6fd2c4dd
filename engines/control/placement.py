"""Body placements: where the target's body stands at given times (a request's ``bodies``).

The control motion says what the target does, not always where it stands: a salsa follower dancing
apart from her leader could be anywhere around him, and the leader's motion does not say where
(``bench/control_oracle.py``). A request can: ``bodies`` lists floor positions ``[x, z]`` (metres,
the control's world frame) of the target's body (its hips on the floor) at given times.

Each placement enters the search as a soft cost on the interpretation distance of every cell whose
segment covers its time: ``weight * |placed body - position|^2`` (m² x s, the units of ``D``), the
body taken from the cell's target segment at that instant, placed by the cell's alignment to the
control (the example's own answer to "where would the target stand here"). The DP then prefers
interpretations that put the body there; after assembly the remaining distance is closed by
:func:`motion.floorfit.floor_correction` within the examples' speed and turn limits, and the
report measures each placement on the output (``body[i]``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .dp import Instances, Interpretation
from .points import sample_cloud

Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


def add_body_costs(
    interp: Interpretation,
    inst: Instances,
    cell_inst: IntArray,
    cell_dur: IntArray,
    body: Array,
    placements: list[tuple[int, Array]],
    weight: float,
) -> None:
    """Add (in place, to ``interp.D``) the cost of every placement to the cells covering it.

    ``body``: ``(F, 3)`` metres, the target's body point in the database's concatenated frames
    (``inst.start`` indexes them); ``placements``: ``(frame at the solve rate, xz (2,) metres)``;
    ``weight``: seconds. A cell ``(s, d)`` ending at ``e`` covers solve frames ``[e - d, e)``; at
    frame ``f`` it plays source frame ``start_s + length_s (f - e + d) / d`` of instance ``s``."""
    D = interp.D
    t_len = D.shape[1] - 1
    durations = np.unique(cell_dur)
    for frame, xz in placements:
        f = int(min(max(frame, 0), t_len - 1))
        for d in durations:
            d = int(d)
            rows = np.flatnonzero(cell_dur == d)
            ends = np.arange(max(f + 1, d), min(f + d, t_len) + 1)
            if ends.size == 0 or rows.size == 0:
                continue
            cells = np.repeat(rows, ends.size)
            at = np.tile(ends, rows.size)
            finite = np.isfinite(D[cells, at])
            cells, at = cells[finite], at[finite]
            if cells.size == 0:
                continue
            s = cell_inst[cells]
            src = inst.start[s] + inst.length[s] * (f - (at - d)) / d
            placed = interp.place(sample_cloud(body, src)[:, None, :], cells, at)[:, 0]  # (n, 3)
            D[cells, at] += weight * ((placed[:, 0] - xz[0]) ** 2 + (placed[:, 2] - xz[1]) ** 2)
