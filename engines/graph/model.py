"""The data a graph database holds, shared by the build (``build.py``, ``hierarchy.py``) and the
search (``search.py``, ``assemble.py``). All arrays; stored in the database npz under ``graph.*``.

Frames are indexed per clip (``0 .. frames[c] - 1``) at the database rate; clips are the motion
library's clips (``engines.library.MotionLibrary``), in order.

Edges
    An edge ``e`` means: play clip ``from_clip[e]`` up to and including frame ``from_frame[e]``, then
    continue with clip ``to_clip[e]`` from frame ``to_frame[e]``. Its ``cost`` is the transition
    cost of that cut (0 for a seamless one; in units of typical frame-to-frame change, see
    ``build.py``). Leaves are the edges of the full graph G; internal nodes of the edge hierarchy
    (tree-structured vector quantization of each clip pair's edges) carry the mean from/to frame
    (rounded) and the mean cost, and are valid transitions themselves. ``parent == -1`` marks the
    roots: the edges of the coarsest graph G'. Children are ``left``/``right`` (-1 for leaves).

Root trajectories
    ``root_xz`` and ``root_yaw`` hold, for every frame of every clip (concatenated, ``offsets[c]``
    is clip c's first row), the root's floor position ``[x, z]`` in metres and the heading in radians
    (``motion.ground`` conventions), used to place pieces and score body constraints quickly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..container import read_only

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
StoredInts = npt.NDArray[np.signedinteger[Any]]
"""Indices as a loaded database stores them (int32) or a build computes them (int64)."""
StoredFloats = npt.NDArray[np.floating[Any]]
"""Numbers as a loaded database stores them (float32) or a build computes them (float64)."""


@dataclass(frozen=True, slots=True)
class EdgeTree:
    """Edges of G and their hierarchy, ``(E,)`` arrays (see the module docstring).

    A built tree holds int64 / float64 arrays; a loaded one (:meth:`from_arrays`) the stored int32
    / float32 ones as they are (read-only views of the database's memory-mapped pages, shared by
    the engine processes of a host). Readers therefore widen what they compute with: index
    arithmetic that can pass 2^31 (``clip * span + frame``) in int64, costs through :meth:`costs`
    (float64, the numbers widening at load gave)."""

    from_clip: StoredInts
    from_frame: StoredInts
    to_clip: StoredInts
    to_frame: StoredInts
    cost: StoredFloats
    parent: StoredInts
    left: StoredInts
    right: StoredInts

    @property
    def size(self) -> int:
        return int(self.from_clip.size)

    @property
    def roots(self) -> IntArray:
        return np.flatnonzero(self.parent < 0).astype(np.int64)

    @property
    def is_leaf(self) -> npt.NDArray[np.bool_]:
        return self.left < 0

    def costs(self, edges: npt.NDArray[np.integer[Any]]) -> FloatArray:
        """The costs of edges ``edges`` (any shape), float64."""
        return np.asarray(self.cost[edges], dtype=np.float64)

    def to_arrays(self, prefix: str = "graph.edges.") -> dict[str, Any]:
        """Stored compactly: int32 indices (clips, frames and node ids stay below 2^31) and float32
        costs (7 digits; costs are compared, never accumulated over many edges); 28 bytes an edge.
        :meth:`from_arrays` keeps them so."""
        out: dict[str, Any] = {}
        for k in _EDGE_FIELDS:
            a = getattr(self, k)
            if k == "cost":
                out[f"{prefix}{k}"] = np.asarray(a, dtype=np.float32)
            else:
                if a.size and (int(a.max()) >= 2**31 or int(a.min()) < -(2**31)):
                    raise ValueError(f"edge field {k} does not fit int32")
                out[f"{prefix}{k}"] = np.asarray(a, dtype=np.int32)
        return out

    @classmethod
    def from_arrays(cls, arrays: Any, prefix: str = "graph.edges.") -> EdgeTree:
        """The stored tree, its arrays as stored (read-only views, not copies; see the class)."""

        def field(name: str, floating: bool = False) -> Any:
            a = np.asarray(arrays[f"{prefix}{name}"])
            want = np.floating if floating else np.integer
            if not np.issubdtype(a.dtype, want):
                raise ValueError(f"{prefix}{name} is {a.dtype}, not {want.__name__}")
            return read_only(a)

        return cls(
            field("from_clip"),
            field("from_frame"),
            field("to_clip"),
            field("to_frame"),
            field("cost", floating=True),
            field("parent"),
            field("left"),
            field("right"),
        )


_EDGE_FIELDS = ("from_clip", "from_frame", "to_clip", "to_frame", "cost", "parent", "left", "right")


@dataclass(frozen=True, slots=True)
class RootTracks:
    """Per-frame root floor position and heading of every clip, concatenated."""

    offsets: IntArray  # (C + 1,) row of each clip's first frame; offsets[-1] = total frames
    root_xz: FloatArray  # (N, 2) metres
    root_yaw: FloatArray  # (N,) radians, unwrapped within each clip

    def frames(self, clip: int) -> int:
        return int(self.offsets[clip + 1] - self.offsets[clip])

    def to_arrays(self, prefix: str = "graph.tracks.") -> dict[str, Any]:
        return {
            f"{prefix}offsets": self.offsets,
            f"{prefix}root_xz": self.root_xz,
            f"{prefix}root_yaw": self.root_yaw,
        }

    @classmethod
    def from_arrays(cls, arrays: Any, prefix: str = "graph.tracks.") -> RootTracks:
        """The stored tracks (float64 as built and stored: read-only views, not copies)."""
        return cls(
            read_only(np.asarray(arrays[f"{prefix}offsets"], dtype=np.int64)),
            read_only(np.asarray(arrays[f"{prefix}root_xz"], dtype=np.float64)),
            read_only(np.asarray(arrays[f"{prefix}root_yaw"], dtype=np.float64)),
        )


@dataclass(frozen=True, slots=True)
class FootContacts:
    """Foot contacts of every library frame (concatenated like :class:`RootTracks`): ``joints (K,)``
    the foot joints (:func:`motion.contacts.foot_joints`), ``flags (N, K)`` booleans from
    :func:`motion.contacts.detect_contacts` on each clip. ``K = 0`` when the skeleton has no
    foot joints."""

    joints: IntArray
    flags: npt.NDArray[np.bool_]

    def to_arrays(self, prefix: str = "graph.contacts.") -> dict[str, Any]:
        return {f"{prefix}joints": self.joints, f"{prefix}flags": self.flags}

    @classmethod
    def from_arrays(cls, arrays: Any, prefix: str = "graph.contacts.") -> FootContacts | None:
        """The stored contacts, or ``None`` for databases built without them."""
        if f"{prefix}joints" not in arrays or f"{prefix}flags" not in arrays:
            return None
        return cls(
            np.asarray(arrays[f"{prefix}joints"], dtype=np.int64),
            read_only(np.asarray(arrays[f"{prefix}flags"], dtype=bool)),
        )


COMPACT_MOTION = ("library.rotations", "library.joint_translations")
"""The motion arrays a graph database stores as float32 (``engines.library.library_to_arrays``
writes float64): joint rotations (unit quaternions, float32 rounding < 1e-7 rad) and animated
joint translations (metres, ~1 micrometre at 10 m). They are 98% of a database's bytes without
it (1,208 of 1,232 bytes a frame on Bandai-Namco, 22 joints); :class:`motion.Motion` reads them
back as float64. Root positions stay float64 (tens of metres from the origin)."""


def compact_motion(motions: Any) -> dict[str, npt.NDArray[Any]]:
    """:data:`COMPACT_MOTION` of ``motions`` (a library's, in order) as float32 arrays, to replace
    the library's float64 ones when the database is stored (the builder adds the engine's arrays
    after the library's: ``workers.execute.build_database_bytes``)."""
    return {
        "library.rotations": np.concatenate([np.asarray(m.rotations, dtype=np.float32) for m in motions]),
        "library.joint_translations": np.concatenate(
            [np.asarray(m.joint_translations, dtype=np.float32) for m in motions]
        ),
    }
