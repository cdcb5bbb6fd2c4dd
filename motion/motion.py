"""A motion clip: a skeleton animated over frames."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .errors import MotionError
from .kinematics import forward_kinematics
from .skeleton import Skeleton
from .units import METRES_PER_UNIT

Array = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Motion:
    """Skeletal animation sampled at a fixed rate.

    Attributes
    ----------
    skeleton:
        The joint hierarchy (offsets in this motion's units).
    root_positions:
        ``(F, 3)`` root joint position per frame, in ``units``, Y up.
    rotations:
        ``(F, J, 4)`` local joint rotations, unit quaternions (x, y, z, w).
    fps:
        Frames per second (> 0).
    joint_translations:
        ``(F, K, 3)`` animated local translations of ``skeleton.translated_joints`` (non-root joints
        with BVH position channels); ``K = 0`` for most skeletons.
    units:
        Length unit of positions and offsets: ``"m"``, ``"cm"``, ``"mm"``, ``"in"``, ``"ft"`` or
        ``"unknown"`` (see :mod:`motion.units`).
    name:
        Where the motion came from (file stem), for messages and provenance.
    """

    skeleton: Skeleton
    root_positions: Array
    rotations: Array
    fps: float
    joint_translations: Array = field(default_factory=lambda: np.zeros((0, 0, 3)))
    units: str = "unknown"
    name: str = ""

    def __post_init__(self) -> None:
        rp = np.asarray(self.root_positions, dtype=np.float64)
        q = np.asarray(self.rotations, dtype=np.float64)
        jt = checked_arrays(self.skeleton, rp, q, np.asarray(self.joint_translations, dtype=np.float64))
        check_rate_and_units(self.fps, self.units)
        object.__setattr__(self, "root_positions", rp)
        object.__setattr__(self, "rotations", q)
        object.__setattr__(self, "joint_translations", jt)
        object.__setattr__(self, "fps", float(self.fps))

    # -- shape -------------------------------------------------------------------------------
    @property
    def num_frames(self) -> int:
        return int(self.root_positions.shape[0])

    @property
    def num_joints(self) -> int:
        return self.skeleton.num_joints

    @property
    def duration_s(self) -> float:
        """Time from the first to the last frame, seconds."""
        return max(self.num_frames - 1, 0) / self.fps

    @property
    def metres_per_unit(self) -> float:
        """Metres in one unit of this motion (1.0 when the units are unknown)."""
        return METRES_PER_UNIT.get(self.units, 1.0)

    # -- kinematics --------------------------------------------------------------------------
    def local_translations(self) -> Array:
        """``(F, J, 3)`` local translation of every joint (offsets, root and animated ones)."""
        t = np.broadcast_to(self.skeleton.offsets, (self.num_frames, self.num_joints, 3)).copy()
        t[:, 0] = self.root_positions
        tj = self.skeleton.translated_joints
        if tj.size:
            t[:, tj] = self.joint_translations
        return t

    def _fk(self, with_rotations: bool) -> tuple[Array, Array | None]:
        if self.skeleton.translated_joints.size == 0:
            return forward_kinematics(
                self.skeleton.parents,
                self.skeleton.offsets,
                self.rotations,
                root_positions=self.root_positions,
                with_rotations=with_rotations,
            )
        return forward_kinematics(
            self.skeleton.parents, self.local_translations(), self.rotations, with_rotations=with_rotations
        )

    def fk(self) -> tuple[Array, Array]:
        """Global ``positions (F, J, 3)`` in this motion's units and ``rotations (F, J, 4)``."""
        pos, grot = self._fk(True)
        if grot is None:  # pragma: no cover - with_rotations=True always returns them
            raise MotionError("forward kinematics returned no rotations")
        return pos, grot

    def global_positions(self) -> Array:
        """``(F, J, 3)`` global joint positions in this motion's units, Y up."""
        return self._fk(False)[0]

    def end_site_positions(self, positions: Array | None = None, rotations: Array | None = None) -> Array:
        """``(F, E, 3)`` global End Site positions (pass ``fk()`` results to avoid recomputing)."""
        if positions is None or rotations is None:
            positions, rotations = self.fk()
        es = self.skeleton.end_site_parents
        return np.asarray(positions[:, es] + rot.rotate(rotations[:, es], self.skeleton.end_site_offsets))

    # -- derived motions ----------------------------------------------------------------------
    def slice(self, start: int, stop: int | None = None) -> Motion:
        """Frames ``start:stop`` (Python slice semantics, at least one frame)."""
        s = slice(start, stop)
        rp = self.root_positions[s]
        if rp.shape[0] == 0:
            raise MotionError(f"frame range {start}:{stop} is empty for a {self.num_frames}-frame motion")
        return replace(
            self,
            root_positions=rp,
            rotations=self.rotations[s],
            joint_translations=self.joint_translations[s],
        )

    def scaled(self, factor: float, units: str | None = None) -> Motion:
        """All lengths multiplied by ``factor`` (optionally relabelling the units)."""
        return replace(
            self,
            skeleton=self.skeleton.scaled(factor),
            root_positions=self.root_positions * factor,
            joint_translations=self.joint_translations * factor,
            units=self.units if units is None else units,
        )

    def to_units(self, units: str) -> Motion:
        """The same motion with lengths expressed in ``units`` (needs known source units)."""
        if units not in METRES_PER_UNIT:
            raise MotionError(f"unknown units {units!r}; use one of {', '.join(METRES_PER_UNIT)}")
        if units == self.units:
            return self
        if self.units == "unknown":
            raise MotionError("the motion's units are unknown; declare them before converting")
        return self.scaled(METRES_PER_UNIT[self.units] / METRES_PER_UNIT[units], units)

    def with_units(self, units: str) -> Motion:
        """Declare the units without changing any number."""
        return replace(self, units=units)


def checked_arrays(
    skeleton: Skeleton,
    root_positions: npt.NDArray[Any],
    rotations: npt.NDArray[Any],
    joint_translations: npt.NDArray[Any],
) -> npt.NDArray[Any]:
    """``joint_translations`` (an ``(F, 0, 3)`` array when empty and the skeleton has no translated
    joints) after checking the shapes of a motion's arrays (:class:`Motion`) against ``skeleton``
    (any dtype: nothing is converted); :class:`MotionError` when they disagree."""
    j = skeleton.num_joints
    rp, q, jt = root_positions, rotations, joint_translations
    f = rp.shape[0] if rp.ndim == 2 else -1
    if rp.shape != (f, 3) or q.shape != (f, j, 4):
        raise MotionError(
            f"motion arrays disagree with the skeleton ({j} joints): root_positions {rp.shape}, "
            f"rotations {q.shape}; expected (F, 3) and (F, {j}, 4)"
        )
    k = skeleton.translated_joints.size
    if jt.size == 0 and k == 0:
        jt = np.zeros((f, 0, 3), dtype=jt.dtype)
    if jt.shape != (f, k, 3):
        raise MotionError(f"joint_translations must be (F, {k}, 3) for this skeleton, got {jt.shape}")
    return jt


def check_rate_and_units(fps: float, units: str) -> None:
    """:class:`MotionError` unless ``fps`` is a positive number and ``units`` known (or ``"unknown"``)."""
    if not (np.isfinite(fps) and fps > 0):
        raise MotionError(f"fps must be a positive number, got {fps}")
    if units not in METRES_PER_UNIT and units != "unknown":
        raise MotionError(f"unknown units {units!r}; use one of {', '.join(METRES_PER_UNIT)}")
