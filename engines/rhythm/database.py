"""The data a rhythm database holds (stored in the database npz under ``rhythm.*``), built by
:func:`engines.rhythm.build.build_rhythm` and loaded by the engine (:meth:`RhythmDatabase.tables`).

``M`` basic movements of ``N`` frames each (``frames_per_beat * beats_per_movement + 1``, at the
database rate ``meta["fps"]``), ``J`` joints, ``K`` animated joint translations (``jt``), ``G``
movement groups (the movement transition graph's nodes), ``B`` beats per movement. Movements are
normalized: each starts at the floor origin facing +Z (``motion.ground`` conventions); positions
are metres, angles radians.

The fields hold the arrays as stored (dtypes below); :meth:`RhythmDatabase.to_arrays` gives
exactly the arrays a database has always stored (names, dtypes, order: a database's content and
bytes do not depend on this class) and :meth:`RhythmDatabase.from_arrays` reads them back
unconverted, so the two are inverse. Movement-graph edits (:mod:`engines.rhythm.choreography`)
replace ``p`` and keep the learned one in ``learned_p``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..base import Arrays
from .blend import fit_blender
from .synth import Tables

Stored = npt.NDArray[Any]

PREFIX = "rhythm."

_REQUIRED = (
    "root",
    "rot",
    "jt",
    "src_clip",
    "src_frames",
    "index_in_clip",
    "end_xz",
    "end_yaw",
    "params",
    "labels",
    "medoids",
    "p",
    "start",
    "kinematic",
    "behavioural",
    "group_distance",
)
"""The arrays every rhythm database stores, in their stored order after ``meta``."""

_NARROWED = ("root", "rot", "jt", "src_frames")
"""Stored as float32 (:meth:`RhythmDatabase.to_arrays` narrows them; synthesis widens ``jt`` and
``src_frames`` back, blends ``root``/``rot`` in float32)."""


@dataclass(frozen=True, slots=True)
class RhythmDatabase:
    """The ``rhythm.*`` part of a database.

    Attributes
    ----------
    meta: settings and facts (JSON): ``frames_per_beat``, ``beats_per_movement``, ``period_s``
        (seconds a beat), ``fps``, ``examples`` (clip names), ``mirrored``, ``leaders``,
        ``followers``, ``beats_s`` (motion beats of each example, seconds), ``groups`` (``G``).
    root: ``(M, N, 3)`` float32 metres, root position of every movement frame.
    rot: ``(M, N, J, 4)`` float32 unit quaternions (signs aligned to each group's medoid).
    jt: ``(M, N, K, 3)`` float32 metres, animated joint translations.
    src_clip: ``(M,)`` int, the library clip each movement was cut from.
    src_frames: ``(M, N)`` float32, fractional source frame of every movement frame.
    index_in_clip: ``(M,)`` int, each movement's place among its clip's movements.
    end_xz: ``(M, 2)`` float64 metres, floor position at the movement's end (movement frame).
    end_yaw: ``(M,)`` float64 radians, heading change over the movement.
    params: ``(M, 2)`` float64 blend parameters (:mod:`engines.rhythm.blend`).
    labels: ``(M,)`` int group of each movement; ``medoids``: ``(G,)`` int, each group's medoid.
    p: ``(G, G)`` float64 transition probabilities (rows sum to 1; 0 = no edge); ``start``:
        ``(G,)`` start distribution; ``kinematic``, ``behavioural``: ``(G, G)`` the two likelihoods
        before mixing; ``group_distance``: ``(G, G)`` (Kim et al. 2003, Eq. 21).
    beat_keys: ``(M, B + 1)`` float64 movement frames of each movement's own beats and
        ``clarity`` ``(M,)`` (:mod:`engines.rhythm.beatkeys`); ``None`` in databases built before
        them (the nominal beat frames are used).
    partner_root, partner_rot: the follower's ``root``/``rot`` (float32) in couple databases, else
        ``None``.
    learned_p: ``(G, G)`` the learned ``p`` once edits replaced it, else ``None``.
    """

    meta: dict[str, Any]
    root: Stored
    rot: Stored
    jt: Stored
    src_clip: Stored
    src_frames: Stored
    index_in_clip: Stored
    end_xz: Stored
    end_yaw: Stored
    params: Stored
    labels: Stored
    medoids: Stored
    p: Stored
    start: Stored
    kinematic: Stored
    behavioural: Stored
    group_distance: Stored
    beat_keys: Stored | None = None
    clarity: Stored | None = None
    partner_root: Stored | None = None
    partner_rot: Stored | None = None
    learned_p: Stored | None = None

    def to_arrays(self) -> Arrays:
        """The stored arrays, ``rhythm.<field>`` (``meta`` as a JSON string), in the stored order."""
        out: Arrays = {PREFIX + "meta": np.array(json.dumps(self.meta))}
        for name in _REQUIRED:
            a = getattr(self, name)
            out[PREFIX + name] = a.astype(np.float32) if name in _NARROWED else a
        if self.beat_keys is not None and self.clarity is not None:
            out[PREFIX + "beat_keys"] = self.beat_keys
            out[PREFIX + "clarity"] = self.clarity
        if self.partner_root is not None and self.partner_rot is not None:
            out[PREFIX + "partner_root"] = self.partner_root.astype(np.float32)
            out[PREFIX + "partner_rot"] = self.partner_rot.astype(np.float32)
        if self.learned_p is not None:
            out[PREFIX + "learned_p"] = self.learned_p
        return out

    @classmethod
    def from_arrays(cls, arrays: Any) -> RhythmDatabase:
        """The ``rhythm.*`` arrays of a stored database, as stored."""

        def optional(name: str) -> Stored | None:
            return np.asarray(arrays[PREFIX + name]) if PREFIX + name in arrays else None

        fields = {name: np.asarray(arrays[PREFIX + name]) for name in _REQUIRED}
        return cls(
            meta=json.loads(str(arrays[PREFIX + "meta"])),
            **fields,
            beat_keys=optional("beat_keys"),
            clarity=optional("clarity"),
            partner_root=optional("partner_root"),
            partner_rot=optional("partner_rot"),
            learned_p=optional("learned_p"),
        )

    def tables(self) -> Tables:
        """What synthesis reads (:class:`engines.rhythm.synth.Tables`)."""
        labels = np.asarray(self.labels, dtype=np.intp)
        params = np.asarray(self.params, dtype=np.float64)
        p, b = int(self.meta["frames_per_beat"]), int(self.meta["beats_per_movement"])
        if self.beat_keys is not None and self.clarity is not None:
            keys = np.asarray(self.beat_keys, dtype=np.float64)
            clarity = np.asarray(self.clarity, dtype=np.float64)
        else:  # databases built before beat keys: the nominal beat frames
            keys = np.broadcast_to(np.arange(b + 1, dtype=np.float64) * p, (labels.size, b + 1)).copy()
            clarity = np.ones(labels.size)
        has_partner = self.partner_root is not None and self.partner_rot is not None
        return Tables(
            root=np.asarray(self.root, dtype=np.float32),
            rot=np.asarray(self.rot, dtype=np.float32),
            jt=np.asarray(self.jt, dtype=np.float64),
            partner_root=np.asarray(self.partner_root, dtype=np.float64) if has_partner else None,
            partner_rot=np.asarray(self.partner_rot, dtype=np.float64) if has_partner else None,
            end_xz=np.asarray(self.end_xz, dtype=np.float64),
            end_yaw=np.asarray(self.end_yaw, dtype=np.float64),
            params=params,
            labels=labels,
            p=np.asarray(self.p, dtype=np.float64),
            start=np.asarray(self.start, dtype=np.float64),
            blender=fit_blender(params, labels),
            frames_per_beat=p,
            beats_per_movement=b,
            fps=float(self.meta["fps"]),
            period_s=float(self.meta["period_s"]),
            src_clip=np.asarray(self.src_clip, dtype=np.intp),
            src_frames=np.asarray(self.src_frames, dtype=np.float64),
            beat_keys=keys,
            clarity=clarity,
        )
