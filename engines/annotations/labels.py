"""The label table of an annotated database: its clips and every frame's labels, read from the
database's manifest arrays only.

What a client needs to look at and correct labels (``GET /v1/databases/{id}/labels``,
:mod:`engines.annotations.corrections`) is the clip names, their lengths, the vocabulary and the
``(N, L)`` label matrix: :meth:`LabelTable.read` reads those five arrays and nothing else,
so with a lazily read database file (:func:`engines.base.open_database`) the motion, the features
and the clusterings stay on disk. The loaded search database (:class:`engines.annotations.search.
Database`) extends it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..base import EngineError, UnknownClipError

IntArray = npt.NDArray[np.intp]

MANIFEST_ARRAYS = ("library.names", "library.frame_counts", "ann.clip_refs", "ann.vocab", "ann.labels")
"""The arrays :meth:`LabelTable.read` reads."""


@dataclass(slots=True)
class LabelTable:
    """Clips and labels of an annotated database (frames of all clips end to end).

    Attributes
    ----------
    names: library clip names; refs: the clips as the spec names them (provenance).
    counts, clip_start: ``(C,)`` frames of each clip and its first database frame.
    vocab: the label vocabulary, ``L`` names.
    labels: ``(N, L)`` int8, +1 / -1 per frame and label (user-given or propagated).
    """

    names: tuple[str, ...]
    refs: tuple[str, ...]
    counts: IntArray
    clip_start: IntArray
    vocab: list[str]
    labels: npt.NDArray[np.int8]

    @classmethod
    def read(cls, arrays: Mapping[str, npt.NDArray[Any]]) -> LabelTable:
        """The table from a database's arrays (only :data:`MANIFEST_ARRAYS` are read)."""
        names = tuple(str(n) for n in np.asarray(arrays["library.names"]).reshape(-1))
        counts = np.asarray(arrays["library.frame_counts"]).astype(np.intp)
        return cls(
            names=names,
            refs=clip_refs(arrays, names),
            counts=counts,
            clip_start=clip_starts(counts),
            vocab=[str(v) for v in np.asarray(arrays["ann.vocab"]).reshape(-1)],
            labels=np.asarray(arrays["ann.labels"], dtype=np.int8),
        )

    def clip_index(self, clip: str) -> int:
        """The index of clip ``clip`` (a library name or the spec's reference); raises
        :class:`~engines.base.UnknownClipError` naming the clips when there is none."""
        if clip in self.names:
            return self.names.index(clip)
        if clip in self.refs:
            return self.refs.index(clip)
        raise UnknownClipError(f"no clip named {clip!r} in the database; clips: {', '.join(self.names[:20])}")

    def frame_of(self, clip: str, frame: int) -> int:
        """Database frame of ``frame`` of clip ``clip``; :class:`EngineError` if there is none."""
        c = self.clip_index(clip)
        if not 0 <= frame < self.counts[c]:
            raise EngineError(f"clip {clip!r} has {int(self.counts[c])} frames; frame {frame} is outside it")
        return int(self.clip_start[c] + frame)


def clip_starts(counts: IntArray) -> IntArray:
    """``(C,)`` first database frame of each clip, from its frame counts."""
    return np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.intp)


def clip_refs(arrays: Mapping[str, npt.NDArray[Any]], names: tuple[str, ...]) -> tuple[str, ...]:
    """The clips as the spec names them (``ann.clip_refs``; the library names for databases built
    before they were stored)."""
    if "ann.clip_refs" not in arrays:
        return names
    refs = tuple(str(r) for r in np.asarray(arrays["ann.clip_refs"]).reshape(-1))
    return refs if len(refs) == len(names) else names
