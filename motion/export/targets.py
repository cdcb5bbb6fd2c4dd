"""Coordinate conventions of export targets (axes, handedness, units).

Segue's internal frame is glTF's: right-handed, Y up, metres, a character facing +Z with its left
along +X. Targets map a point ``p`` to ``scale * (M @ p)``:

========  =====================================  ==========================================
target    axes                                   M (rows = target axes in internal terms)
========  =====================================  ==========================================
gltf      right-handed, Y up, +Z forward, m      identity
godot     same as glTF (Godot imports glTF as is) identity
unity     left-handed, Y up, +Z forward, m        x -> -x (what Unity's glTF importers do)
unreal    left-handed, Z up, +X forward, cm       (X, Y, Z) = (z, -x, y) * 100
========  =====================================  ==========================================

Rotations transform as ``R' = M R M^T`` (a proper rotation even when M is a reflection).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..errors import ExportError
from ..motion import Motion
from ..skeleton import Skeleton

Array = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class Target:
    """An export convention: ``basis`` (3x3, internal -> target axes) and target ``units``."""

    name: str
    basis: Array
    units: str
    handedness: str
    up: str
    forward: str

    @property
    def metres_to_units(self) -> float:
        return {"m": 1.0, "cm": 100.0}[self.units]

    def describe(self) -> dict[str, str]:
        return {
            "target": self.name,
            "handedness": self.handedness,
            "up": self.up,
            "forward": self.forward,
            "units": self.units,
        }


TARGETS: dict[str, Target] = {
    "gltf": Target("gltf", np.eye(3), "m", "right", "+Y", "+Z"),
    "godot": Target("godot", np.eye(3), "m", "right", "+Y", "+Z"),
    "unity": Target("unity", np.diag([-1.0, 1.0, 1.0]), "m", "left", "+Y", "+Z"),
    "unreal": Target(
        "unreal", np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), "cm", "left", "+Z", "+X"
    ),
}


def get_target(name: str) -> Target:
    """The target called ``name`` (:class:`ExportError` listing the choices otherwise)."""
    try:
        return TARGETS[name.lower()]
    except KeyError:
        raise ExportError(f"unknown target {name!r}; use one of {', '.join(TARGETS)}") from None


def transform_points(points: Array, target: Target, metres_per_unit: float) -> Array:
    """Points ``(..., 3)`` in a motion's units -> the target's axes and units."""
    scale = metres_per_unit * target.metres_to_units
    return np.asarray(np.asarray(points, dtype=np.float64) @ target.basis.T * scale)


def transform_rotations(q: Array, target: Target) -> Array:
    """Quaternions ``(..., 4)`` -> the target's axes (``M R M^T``)."""
    if np.array_equal(target.basis, np.eye(3)):
        return np.asarray(q, dtype=np.float64)
    m = target.basis
    mats = rot.to_matrix(np.asarray(q, dtype=np.float64))
    return rot.from_matrix(m @ mats @ m.T)


def to_target(motion: Motion, target: str | Target) -> Motion:
    """The motion expressed in a target convention (lengths converted; units relabelled).

    Global positions of the result equal ``transform_points`` of the original's, and its BVH
    channels describe the same animation in the target's axes.
    """
    tgt = get_target(target) if isinstance(target, str) else target
    if tgt.name in ("gltf", "godot") and motion.units == "m":
        return motion
    mpu = motion.metres_per_unit
    sk = motion.skeleton
    new_sk = Skeleton(
        sk.names,
        sk.parents,
        transform_points(sk.offsets, tgt, mpu),
        sk.channels,
        sk.end_site_parents,
        transform_points(sk.end_site_offsets, tgt, mpu),
    )
    return replace(
        motion,
        skeleton=new_sk,
        root_positions=transform_points(motion.root_positions, tgt, mpu),
        rotations=transform_rotations(motion.rotations, tgt),
        joint_translations=transform_points(motion.joint_translations, tgt, mpu),
        units=tgt.units,
    )
