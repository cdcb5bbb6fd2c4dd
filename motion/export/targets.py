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

Every export to a target is written in the target's units unless the caller overrides them
(:func:`output_units`): BVH, JSON frames and NPZ alike. GLB is always metres (glTF 2.0 says so).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..errors import ExportError
from ..motion import Motion
from ..skeleton import Skeleton
from ..units import METRES_PER_UNIT

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


def transform_points(
    points: Array, target: Target, metres_per_unit: float, units: str | None = None
) -> Array:
    """Points ``(..., 3)`` in a motion's units -> the target's axes and units (or ``units``)."""
    scale = metres_per_unit / METRES_PER_UNIT[units if units is not None else target.units]
    return np.asarray(np.asarray(points, dtype=np.float64) @ target.basis.T * scale)


def transform_rotations(q: Array, target: Target) -> Array:
    """Quaternions ``(..., 4)`` -> the target's axes (``M R M^T``)."""
    if np.array_equal(target.basis, np.eye(3)):
        return np.asarray(q, dtype=np.float64)
    m = target.basis
    mats = rot.to_matrix(np.asarray(q, dtype=np.float64))
    return rot.from_matrix(m @ mats @ m.T)


def output_units(target: str | Target, units: str | None = None) -> str:
    """The length unit an export to ``target`` is written in: ``units`` when given (an
    override), else the target's own (metres for gltf/godot/unity, centimetres for unreal)."""
    tgt = get_target(target) if isinstance(target, str) else target
    if units is None:
        return tgt.units
    if units not in METRES_PER_UNIT:
        raise ExportError(f"unknown units {units!r}; use one of {', '.join(METRES_PER_UNIT)}")
    return units


def to_target(motion: Motion, target: str | Target, units: str | None = None) -> Motion:
    """The motion expressed in a target convention: its axes, and its units (the target's own, or
    ``units`` as an override; see :func:`output_units`). A motion of unknown units is taken as
    metres.

    Global positions of the result equal ``transform_points`` of the original's, and its BVH
    channels describe the same animation in the target's axes.
    """
    tgt = get_target(target) if isinstance(target, str) else target
    out_units = output_units(tgt, units)
    identity_axes = bool(np.array_equal(tgt.basis, np.eye(3)))
    if identity_axes and motion.units == out_units:
        return motion
    if identity_axes and motion.units != "unknown":
        return motion.to_units(out_units)
    mpu = motion.metres_per_unit
    sk = motion.skeleton
    new_sk = Skeleton(
        sk.names,
        sk.parents,
        transform_points(sk.offsets, tgt, mpu, out_units),
        sk.channels,
        sk.end_site_parents,
        transform_points(sk.end_site_offsets, tgt, mpu, out_units),
    )
    return replace(
        motion,
        skeleton=new_sk,
        root_positions=transform_points(motion.root_positions, tgt, mpu, out_units),
        rotations=transform_rotations(motion.rotations, tgt),
        joint_translations=transform_points(motion.joint_translations, tgt, mpu, out_units),
        units=out_units,
    )
