"""Regions of the floor (obstacles): discs and simple polygons, and how deep points are inside.

Floor points are ``[x, z]`` metres (DESIGN.md conventions). A region's :meth:`FloorRegion.depth`
is 0 outside and the distance to the boundary inside, so "how far into the obstacle" reads
directly in metres; ``margin`` grows the region (a search keeps the frames between its samples
out by testing a slightly larger region).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .errors import MotionError

Array = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class FloorRegion:
    """A disc (``center (2,)``, ``radius``) or a simple polygon ``(V, 2)`` on the floor, metres."""

    center: Array | None = None
    radius: float = 0.0
    polygon: Array | None = None

    def __post_init__(self) -> None:
        if (self.center is None) == (self.polygon is None):
            raise MotionError("a floor region is exactly one of a disc (center, radius) or a polygon")
        if self.center is not None and not self.radius > 0:
            raise MotionError(f"a disc needs a positive radius, got {self.radius}")
        if self.polygon is not None and np.asarray(self.polygon).shape[0] < 3:
            raise MotionError("a polygon needs at least 3 vertices")

    @classmethod
    def disc(cls, center: npt.ArrayLike, radius: float) -> FloorRegion:
        return cls(center=np.asarray(center, dtype=np.float64).reshape(2), radius=float(radius))

    @classmethod
    def from_polygon(cls, vertices: npt.ArrayLike) -> FloorRegion:
        return cls(polygon=np.asarray(vertices, dtype=np.float64).reshape(-1, 2))

    def depth(self, points: Array, margin: float = 0.0) -> Array:
        """How far (metres) floor points ``(..., 2)`` are inside the region grown by ``margin``
        metres (0 outside), shape ``(...)``."""
        if self.center is not None:
            d = self.radius + margin - np.linalg.norm(points - self.center, axis=-1)
            return np.asarray(np.maximum(d, 0.0))
        if self.polygon is None:  # pragma: no cover - __post_init__ guarantees one shape
            raise MotionError("a floor region without a shape")
        return polygon_depth(points, self.polygon, margin)


def polygon_depth(points: Array, polygon: Array, margin: float = 0.0) -> Array:
    """How far ``(...)`` points ``(..., 2)`` are inside a simple polygon ``(V, 2)`` grown by
    ``margin`` metres: ``margin`` + the distance to the boundary inside (even-odd rule),
    ``margin`` - that distance outside, never below 0."""
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    p = points[..., None, :]  # (..., 1, 2)
    ax, az, bx, bz = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
    px, pz = p[..., 0], p[..., 1]
    crosses = (az > pz) != (bz > pz)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = ax + (pz - az) * (bx - ax) / (bz - az)
    inside = (np.count_nonzero(crosses & (px < x_at), axis=-1) % 2) == 1
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    dist = np.linalg.norm(p - (a + t[..., None] * ab), axis=-1).min(axis=-1)
    return np.asarray(np.maximum(np.where(inside, margin + dist, margin - dist), 0.0))
