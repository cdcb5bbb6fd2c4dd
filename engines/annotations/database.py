"""The data an annotated database holds beside its motion library (stored in the database npz under
``ann.*``), built by :mod:`engines.annotations.build` and read by the search
(:meth:`engines.annotations.search.Database.from_arrays`).

``C`` clips, ``F`` database frames (all clips end to end, at the database rate), ``L`` labels,
``d`` continuity-feature dimensions, ``B`` block sizes. Positions are metres, angles radians
(``motion.ground`` conventions).

The fields hold the arrays as stored; :meth:`AnnotatedDatabase.to_arrays` gives exactly the arrays
a database has always stored (names, dtypes, order: a database's content and bytes do not depend on
this class) and :meth:`AnnotatedDatabase.from_arrays` reads them back unconverted, so the two are
inverse. The label table alone (for label queries without loading the rest) is read by
:class:`engines.annotations.labels.LabelTable`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..base import Arrays

PREFIX = "ann."


@dataclass(frozen=True, slots=True)
class AnnotatedDatabase:
    """The ``ann.*`` part of a database.

    Attributes
    ----------
    clip_refs: ``(C,)`` str, each clip as the spec names it (its ``name``, else its ``bvh``
        reference as written), used in provenance; ``None`` if absent (the library names stand
        for them, :func:`engines.annotations.labels.clip_refs`).
    vocab: ``(L,)`` str, the labels.
    labels: ``(F, L)`` int8, +1/-1 per database frame (the user's labels where given, the SVMs'
        elsewhere).
    known: ``(F, L)`` bool, user-given.
    decision: ``(F, L)`` float32, signed confidence of the labels (SVM decision values,
        :mod:`engines.annotations.propagate`).
    report: JSON, per label the training counts, chosen gamma and cross-validated precision,
        recall and F1 (stored as a 0-d str array).
    features: ``(F, d)`` float32, continuity features ``F(f)``
        (:func:`engines.annotations.blocks.pca_features`); ``pca_mean`` ``(D,)`` and
        ``pca_components`` ``(d, D)`` float64, the projection that made them (``D`` raw
        window-feature dimensions).
    ground_xz: ``(F, 2)`` float64 metres and ``ground_yaw`` ``(F,)`` float64 radians: each frame's
        body position and heading (to place blocks and for end constraints).
    block_sizes: ``(B,)`` int64, frames; ``clusters``: per block size (in ``block_sizes`` order),
        ``(F,)`` int32 the cluster of the block of that size starting at each frame (-1: none fits),
        stored as ``ann.clusters.<size>``.
    """

    clip_refs: npt.NDArray[np.str_] | None
    vocab: npt.NDArray[np.str_]
    labels: npt.NDArray[np.int8]
    known: npt.NDArray[np.bool_]
    decision: npt.NDArray[np.float32]
    report: str
    features: npt.NDArray[np.float32]
    pca_mean: npt.NDArray[np.float64]
    pca_components: npt.NDArray[np.float64]
    ground_xz: npt.NDArray[np.float64]
    ground_yaw: npt.NDArray[np.float64]
    block_sizes: npt.NDArray[np.int64]
    clusters: dict[int, npt.NDArray[np.int32]]

    def to_arrays(self) -> Arrays:
        """The stored arrays, ``ann.<field>`` then ``ann.clusters.<size>``, in the stored order."""
        out: Arrays = {} if self.clip_refs is None else {PREFIX + "clip_refs": self.clip_refs}
        out |= {
            PREFIX + "vocab": self.vocab,
            PREFIX + "labels": self.labels,
            PREFIX + "known": self.known,
            PREFIX + "decision": self.decision,
            PREFIX + "report": np.array(self.report),
            PREFIX + "features": self.features,
            PREFIX + "pca_mean": self.pca_mean,
            PREFIX + "pca_components": self.pca_components,
            PREFIX + "ground_xz": self.ground_xz,
            PREFIX + "ground_yaw": self.ground_yaw,
            PREFIX + "block_sizes": self.block_sizes,
        }
        for size, cl in self.clusters.items():
            out[f"{PREFIX}clusters.{size}"] = cl
        return out

    @classmethod
    def from_arrays(cls, arrays: Any) -> AnnotatedDatabase:
        """The ``ann.*`` arrays of a stored database, as stored."""

        def get(name: str) -> Any:
            return np.asarray(arrays[PREFIX + name])

        sizes = get("block_sizes")
        return cls(
            clip_refs=get("clip_refs") if PREFIX + "clip_refs" in arrays else None,
            vocab=get("vocab"),
            labels=get("labels"),
            known=get("known"),
            decision=get("decision"),
            report=str(arrays[PREFIX + "report"]),
            features=get("features"),
            pca_mean=get("pca_mean"),
            pca_components=get("pca_components"),
            ground_xz=get("ground_xz"),
            ground_yaw=get("ground_yaw"),
            block_sizes=sizes,
            clusters={int(s): get(f"clusters.{int(s)}") for s in sizes.reshape(-1)},
        )
