"""What a retargeting did to the feet, measured on its result: the figures ``segue retarget``
prints and writes with ``--report``.

* ``sink_cm``: how far the character's soles (:mod:`motion.retarget.sole`: its skinned mesh's
  lowest foot vertices, or soles made from its bones) go under its floor, at worst;
* ``planted_lift_cm``: how far a planted sole (a plant of :func:`sole_plants`, the contact
  events' plants: from where the sole lands to where it leaves the floor) is above the floor, at
  worst;
* ``foot_speed_m_s``: the fastest foot joint (ankle or toe) of the result, frame to frame, against
  ``source_foot_speed_m_s``, the source's fastest foot (:func:`fastest_foot`: its ankle and toe,
  or the foot's tip where it has no toe joint) scaled to the character (by the ratio of the two
  skeletons' legs, thigh plus shin, in their rest poses), and their ``foot_speed_ratio``;
* ``contacts``: the result's foot plants (one per plant, whichever of the foot's joints
  touches: its contact events) and ``source_plants``, the source's.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt

from ..contacts import foot_plants
from ..motion import Motion
from .legik import foot_groups_of
from .names import Correspondence
from .sole import SIDES, Sole
from .transfer import Pose, leg_length, tip_positions, zero_pose

Array = npt.NDArray[np.float64]


ON_FLOOR_M = 0.01
"""A sole is on the floor while its lowest point is within this many metres of it."""


def sole_plants(
    motion: Motion,
    groups: list[tuple[int, ...]],
    soles: tuple[Sole, ...],
    floor: float,
    pose: tuple[Array, Array] | None = None,
) -> list[tuple[int, int, int]]:
    """The plants of ``motion`` (a character, its ``soles`` standing on ``floor``, its units) as
    its contact events give them: each plant of :func:`motion.contacts.foot_plants` (one per plant
    of its ankle and toe joints, ``groups``: the feet ankle first, sides in :data:`SIDES` order)
    from the frame its sole lands on the floor (lowest point within :data:`ON_FLOOR_M`) to the
    frame after it last touches it: a joint's plant starts before the sole lands (a heel coming
    down slowly) and ends after it leaves (a toe rising slowly). A plant whose sole never reaches
    the floor is none. ``(group index, start, end exclusive)``. ``pose``: ``motion.fk()`` when the
    caller has it."""
    pos, grot = pose if pose is not None else motion.fk()
    by_side = {s.side: s for s in soles}
    near = ON_FLOOR_M / motion.metres_per_unit
    on: dict[int, npt.NDArray[np.bool_]] = {}
    out = []
    for g, a, b in foot_plants(motion, groups, positions=pos):
        sole = by_side.get(SIDES[g]) if g < len(SIDES) else None
        if sole is None:
            out.append((g, a, b))
            continue
        if g not in on:
            on[g] = sole.positions(pos, grot)[:, :, 1].min(axis=1) - floor <= near
        touching = np.flatnonzero(on[g][a:b])
        if touching.size:
            out.append((g, a + int(touching[0]), a + int(touching[-1]) + 1))
    return out


@dataclass(frozen=True, slots=True)
class FeetReport:
    """The figures of the module docstring (centimetres, metres per second, counts)."""

    sink_cm: float
    planted_lift_cm: float | None
    foot_speed_m_s: float
    source_foot_speed_m_s: float
    foot_speed_ratio: float | None
    contacts: int
    source_plants: int

    def as_dict(self) -> dict[str, float | int | None]:
        return asdict(self)

    def summary(self) -> str:
        """One line for people."""
        lift = "no plant" if self.planted_lift_cm is None else f"{self.planted_lift_cm:.1f} cm"
        ratio = "" if self.foot_speed_ratio is None else f" ({self.foot_speed_ratio:.2f} of the source's"
        return (
            f"soles at worst {self.sink_cm:.1f} cm under the floor, planted soles within {lift} of it; "
            f"fastest foot {self.foot_speed_m_s:.2f} m/s{ratio} {self.source_foot_speed_m_s:.2f}, scaled)"
            f"; {self.contacts} contacts for the source's {self.source_plants} plants"
        )


def fastest_foot(motion: Motion, roles: dict[str, int]) -> float:
    """The fastest foot of ``motion``, m/s frame to frame: its ankle and toe joints (roles
    ``LeftFoot``, ``LeftToes``, ...) and, for a foot without a toe joint (CMU motions), the tip of
    the foot (its End Site or child: where a toe joint would be, and beyond)."""
    if motion.num_frames < 2:
        return 0.0
    pose = Pose.of(motion)
    tips = None
    points = []
    for side in ("Left", "Right"):
        if side + "Foot" not in roles:
            continue
        points.append(pose.positions[:, roles[side + "Foot"]])
        if side + "Toes" in roles:
            points.append(pose.positions[:, roles[side + "Toes"]])
        else:
            tips = tip_positions(motion, pose) if tips is None else tips
            points.append(tips[:, roles[side + "Foot"]])
    if not points:
        return 0.0
    pos = np.stack(points, axis=1) * motion.metres_per_unit
    return float((np.linalg.norm(np.diff(pos, axis=0), axis=-1) * motion.fps).max())


def feet_report(
    source: Motion,
    result: Motion,
    character: Motion,
    corr: Correspondence,
    soles: tuple[Sole, ...],
    floor: float,
    plants: list[tuple[int, int, int]] | None = None,
) -> FeetReport:
    """The figures of ``result`` (``source`` retargeted onto ``character``, in its rest pose at
    frame 0, with correspondence ``corr``), its ``soles`` and their ``floor`` (character units).
    ``plants``: :func:`sole_plants` of the result when the caller has them (its contact events)."""
    tr, sr = corr.target_roles, corr.source_roles
    groups = foot_groups_of(tr)
    pos, grot = result.fk()
    m = result.metres_per_unit
    lowest = {s.side: s.positions(pos, grot)[:, :, 1].min(axis=1) - floor for s in soles}
    guards = [
        float(s.guard.positions(pos, grot)[:, :, 1].min()) - floor for s in soles if s.guard is not None
    ]
    sink = max(0.0, -min([*(float(v.min()) for v in lowest.values()), *guards])) * m
    if plants is None:
        plants = sole_plants(result, groups, soles, floor, (pos, grot))
    lifts = [lowest[("Left", "Right")[g]][a:b].max() for g, a, b in plants if ("Left", "Right")[g] in lowest]
    scale = (leg_length(character.global_positions()[0], tr) * character.metres_per_unit) / max(
        leg_length(zero_pose(source).global_positions()[0], sr) * source.metres_per_unit, 1e-300
    )
    fastest = fastest_foot(result, tr)
    src = fastest_foot(source, sr) * scale
    return FeetReport(
        sink_cm=round(100.0 * sink, 2),
        planted_lift_cm=round(100.0 * m * max(0.0, float(max(lifts))), 2) if lifts else None,
        foot_speed_m_s=round(fastest, 3),
        source_foot_speed_m_s=round(src, 3),
        foot_speed_ratio=round(fastest / src, 3) if src > 0 else None,
        contacts=len(plants),
        source_plants=len(foot_plants(source)),
    )
