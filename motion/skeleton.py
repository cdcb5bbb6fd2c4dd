"""The static part of a character: joint names, hierarchy, offsets, End Sites and BVH channel layout."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .errors import MotionError

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
VALID_CHANNELS = frozenset(POSITION_CHANNELS + ROTATION_CHANNELS)
DEFAULT_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
DEFAULT_JOINT_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy.

    Attributes
    ----------
    names:
        ``J`` unique joint names; joint 0 is the root.
    parents:
        ``(J,)`` int, parent index of each joint, ``-1`` for the root; parents precede children.
    offsets:
        ``(J, 3)`` float, each joint's rest translation from its parent, in the skeleton's units
        (the root's offset is its rest position).
    channels:
        Per joint, the BVH channel names in file order, e.g. ``("Zrotation", "Xrotation",
        "Yrotation")``. Rotation channels give the intrinsic Euler order; position channels replace
        the offset on their axis.
    end_site_parents, end_site_offsets:
        ``(E,)`` joint index and ``(E, 3)`` offset of each End Site (leaf markers without channels).
    """

    names: tuple[str, ...]
    parents: npt.NDArray[np.intp]
    offsets: npt.NDArray[np.float64]
    channels: tuple[tuple[str, ...], ...]
    end_site_parents: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    end_site_offsets: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    _translated: npt.NDArray[np.intp] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        j = len(self.names)
        parents = np.asarray(self.parents, dtype=np.intp).reshape(-1)
        offsets = np.asarray(self.offsets, dtype=np.float64)
        es_par = np.asarray(self.end_site_parents, dtype=np.intp).reshape(-1)
        es_off = np.asarray(self.end_site_offsets, dtype=np.float64).reshape(-1, 3)
        if j == 0:
            raise MotionError("a skeleton needs at least one joint")
        if parents.shape != (j,) or offsets.shape != (j, 3) or len(self.channels) != j:
            raise MotionError(
                f"skeleton arrays disagree: {j} names, parents {parents.shape}, offsets {offsets.shape}, "
                f"{len(self.channels)} channel lists"
            )
        if len(set(self.names)) != j:
            dup = sorted({n for n in self.names if self.names.count(n) > 1})
            raise MotionError(f"duplicate joint names: {', '.join(dup)}")
        if parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, j)):
            raise MotionError("parents must be -1 for joint 0 and precede each other joint")
        if es_par.shape[0] != es_off.shape[0] or np.any((es_par < 0) | (es_par >= j)):
            raise MotionError("End Site parents must index joints")
        if not np.all(np.isfinite(offsets)) or not np.all(np.isfinite(es_off)):
            raise MotionError("skeleton offsets must be finite")
        for name, chans in zip(self.names, self.channels, strict=True):
            bad = [c for c in chans if c not in VALID_CHANNELS]
            if bad or len(set(chans)) != len(chans):
                raise MotionError(f"joint {name!r}: invalid channels {list(chans)}")
        for arr in (parents, offsets, es_par, es_off):
            arr.setflags(write=False)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "end_site_parents", es_par)
        object.__setattr__(self, "end_site_offsets", es_off)
        object.__setattr__(self, "channels", tuple(tuple(c) for c in self.channels))
        object.__setattr__(self, "names", tuple(self.names))
        translated = np.array([k for k in range(1, j) if self.position_axes(k)], dtype=np.intp)
        translated.setflags(write=False)
        object.__setattr__(self, "_translated", translated)

    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    def index(self, name: str) -> int:
        """Index of the joint called ``name`` (:class:`MotionError` when absent)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise MotionError(f"no joint named {name!r}") from None

    def rotation_order(self, joint: int) -> str:
        """Intrinsic Euler order of the joint's rotation channels, e.g. ``"ZXY"`` ('' if none)."""
        return "".join(c[0] for c in self.channels[joint] if c.endswith("rotation"))

    def position_axes(self, joint: int) -> tuple[int, ...]:
        """Axes (0=X, 1=Y, 2=Z) carried by the joint's position channels, in file order."""
        return tuple("XYZ".index(c[0]) for c in self.channels[joint] if c.endswith("position"))

    @property
    def translated_joints(self) -> npt.NDArray[np.intp]:
        """Indices of non-root joints with position channels (animated translations), ``(K,)``
        (read-only; found once, when the skeleton is made: motions ask for it at every step)."""
        return self._translated

    def children(self, joint: int) -> list[int]:
        return [int(c) for c in np.flatnonzero(self.parents == joint)]

    def depth(self) -> npt.NDArray[np.intp]:
        """``(J,)`` number of ancestors of each joint."""
        d = np.zeros(self.num_joints, dtype=np.intp)
        for j in range(1, self.num_joints):
            d[j] = d[self.parents[j]] + 1
        return d

    def scaled(self, factor: float) -> Skeleton:
        """The same skeleton with every length multiplied by ``factor``."""
        return Skeleton(
            self.names,
            self.parents,
            self.offsets * factor,
            self.channels,
            self.end_site_parents,
            self.end_site_offsets * factor,
        )

    def same_structure(self, other: Skeleton) -> bool:
        """True when names and parents agree (offsets may differ)."""
        return self.names == other.names and bool(np.array_equal(self.parents, other.parents))


def default_channels(num_joints: int) -> tuple[tuple[str, ...], ...]:
    """A BVH channel layout for generated skeletons: 6 channels on the root, ZYX rotations elsewhere."""
    return (DEFAULT_ROOT_CHANNELS,) + (DEFAULT_JOINT_CHANNELS,) * (num_joints - 1)
