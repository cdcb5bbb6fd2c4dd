"""Blender's axes (Z up, a character facing -Y, metres) and Segue's (glTF's: Y up, facing +Z).

A point ``(x, y, z)`` in Blender is ``(x, z, -y)`` in Segue, so a floor position ``[x, z]`` in
Segue is ``[x, -y]`` in Blender, and Segue's heading (degrees about +Y, 0 facing +Z, 90 facing
+X) is a Blender direction ``(dx, dy)`` as ``atan2(dx, -dy)``: an unrotated empty or character,
facing -Y, has heading 0; one facing +X has 90.

:class:`SegueFrame` is where a generation happens: Segue's origin at an anchor on Blender's
floor, and floor lengths divided by the character's size relative to the database's performers
(Segue scales a root path by that ratio about its origin when it puts a motion on a character:
docs/retargeting.md), so that the character's own hips meet the goals placed for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from . import mat4
from .mat4 import Mat4, Vec3

GLTF_FROM_BLENDER: Mat4 = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
"""Blender world -> glTF/Segue world (what Blender's glTF exporter applies with +Y up)."""
BLENDER_FROM_GLTF: Mat4 = mat4.inverse(GLTF_FROM_BLENDER)


def to_segue(p: tuple[float, float, float]) -> Vec3:
    """A Blender point (Z up) in Segue's axes (Y up)."""
    return (float(p[0]), float(p[2]), -float(p[1]))


def to_blender(p: tuple[float, float, float]) -> Vec3:
    """A Segue point (Y up) in Blender's axes (Z up)."""
    return (float(p[0]), -float(p[2]), float(p[1]))


def heading_deg(direction: tuple[float, ...]) -> float:
    """Segue's heading (degrees, 0 = +Z, 90 = +X) of a Blender floor direction ``(dx, dy, ...)``;
    ``ValueError`` for a direction with no floor component."""
    dx, dy = float(direction[0]), float(direction[1])
    if math.hypot(dx, dy) < 1e-9:
        raise ValueError("the direction is vertical: it has no heading on the floor")
    return math.degrees(math.atan2(dx, -dy))


def blender_direction(heading: float) -> tuple[float, float]:
    """The Blender floor direction ``(dx, dy)`` of a Segue heading (degrees)."""
    h = math.radians(heading)
    return (math.sin(h), -math.cos(h))


@dataclass(frozen=True, slots=True)
class SegueFrame:
    """Segue's world for one generation: its origin at ``anchor`` (a Blender point on the floor)
    and floor lengths divided by ``scale`` (the character's size over the database performers':
    Segue's retargeting multiplies the root path by it about the origin)."""

    anchor: tuple[float, float] = (0.0, 0.0)
    scale: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"scale must be a positive number, not {self.scale!r}")

    def floor(self, p: tuple[float, ...]) -> tuple[float, float]:
        """Segue's ``[x, z]`` (metres, for the database's performers) of a Blender point."""
        return ((float(p[0]) - self.anchor[0]) / self.scale, -(float(p[1]) - self.anchor[1]) / self.scale)

    def length(self, metres: float) -> float:
        """A length on the character's scale as the performers' (a speed too)."""
        return metres / self.scale

    def placement(self) -> Mat4:
        """The Blender world transform of a result's Segue origin (a translation to the anchor)."""
        return (1.0, 0.0, 0.0, self.anchor[0], 0.0, 1.0, 0.0, self.anchor[1], 0.0, 0.0, 1.0, 0.0,
                0.0, 0.0, 0.0, 1.0)  # fmt: skip
