"""Building an annotated database: label propagation, continuity features, block clusterings.

Arrays stored beside the motion library (all numeric or str, JSON in 0-d str arrays):

* ``ann.clip_refs`` ``(C,)`` str: each clip as the spec names it (its ``name``, else its ``bvh``
  reference as written), used in provenance.
* ``ann.vocab`` ``(L,)`` str; ``ann.labels`` ``(F, L)`` int8 +1/-1 per database frame (the user's
  labels where given, the SVMs' elsewhere); ``ann.known`` ``(F, L)`` bool (user-given);
  ``ann.decision`` ``(F, L)`` float32 signed confidence of the labels (SVM decision values;
  see :mod:`engines.annotations.propagate`); ``ann.report`` JSON: per label the
  training counts, chosen gamma and cross-validated precision / recall / F1.
* ``ann.features`` ``(F, d)`` float32: ``F(f)`` (:func:`engines.annotations.blocks.pca_features`).
* ``ann.ground_xz`` ``(F, 2)`` metres and ``ann.ground_yaw`` ``(F,)`` radians: each frame's body
  position and heading (the cached root transforms used to place blocks and for end constraints).
* ``ann.block_sizes`` ``(B,)``; ``ann.clusters.<size>`` ``(F,)`` int32 cluster of the block of that
  size starting at each frame (-1: none fits).
"""

from __future__ import annotations

from typing import overload

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

from motion.ground import body_joints
from schemas.annotations import AnnotatedDatabaseSpec

from ..base import Arrays, Emitter, ShouldStop
from ..library import MotionLibrary
from .blocks import cluster_blocks, pca_features, principal_axes
from .database import AnnotatedDatabase
from .features import (
    clip_frames,
    continuity_raw,
    embedding_offsets,
    svm_joint_indices,
    window_embedding,
    window_offsets,
)
from .propagate import SvmEmbedding, propagate

FloatArray = npt.NDArray[np.float64]

BLAS_THREADS = 1
"""BLAS threads during a build and a search (small matrices; workers already run in parallel)."""

SVM_DIMS = 48
"""The standardized window embedding is PCA-reduced to at most this many dimensions (speeds up the
SVMs; keeps well over 95% of the variance on Bandai-Namco)."""


def _check(should_stop: ShouldStop) -> None:
    if should_stop():
        raise InterruptedError("build stopped")


def embed_library(
    library: MotionLibrary, spec: AnnotatedDatabaseSpec
) -> tuple[SvmEmbedding, FloatArray, FloatArray, FloatArray]:
    """Per database frame: the SVM window embedding (raw metres; ``combined`` ``(F, E)``, and with
    ``spec.refine_changes`` and a context window also its ``fine`` window columns ``(F, E_f)``,
    ``reach`` half the context window in frames), the continuity input ``(F, 3, D)``, ground
    positions ``(F, 2)`` m and headings ``(F,)`` rad."""
    sk = library.motions[0].skeleton
    svm_j = svm_joint_indices(sk, spec.svm_joints)
    body = body_joints(sk)
    offsets = embedding_offsets(
        library.fps, spec.window_s, spec.window_samples, spec.context_s, spec.context_samples
    )
    fine_offsets = window_offsets(library.fps, spec.window_s, spec.window_samples)
    reach = int(round(0.5 * spec.context_s * library.fps))
    refine = bool(spec.refine_changes) and reach > 0 and offsets.size > fine_offsets.size
    emb, raw, xzs, yaws = [], [], [], []
    for m in library.motions:
        pos, xz, yaw = clip_frames(m)
        emb.append(window_embedding(pos, xz, yaw, svm_j, offsets))
        raw.append(continuity_raw(pos, xz, yaw, body, m.fps))
        xzs.append(xz)
        yaws.append(yaw)
    combined = np.concatenate(emb)
    fine = None
    if refine:  # columns are (sample, joint, xyz), samples in the order of offsets
        per = 3 * svm_j.size
        cols = [i * per + q for i in np.flatnonzero(np.isin(offsets, fine_offsets)) for q in range(per)]
        fine = combined[:, cols]
    svm = SvmEmbedding(combined, fine, reach if refine else 0)
    return svm, np.concatenate(raw), np.concatenate(xzs), np.concatenate(yaws)


@overload
def standardize(x: FloatArray, dims: int, seed: int = 0, sample: int = 20_000) -> FloatArray: ...


@overload
def standardize(x: SvmEmbedding, dims: int, seed: int = 0, sample: int = 20_000) -> SvmEmbedding: ...


def standardize(
    x: FloatArray | SvmEmbedding, dims: int, seed: int = 0, sample: int = 20_000
) -> FloatArray | SvmEmbedding:
    """Columns to zero mean and unit variance, then the leading ``dims`` principal components
    (``(F, min(E, dims))``; of each part of an :class:`SvmEmbedding`)."""
    if isinstance(x, SvmEmbedding):
        fine = None if x.fine is None else standardize(x.fine, dims, seed, sample)
        return SvmEmbedding(standardize(x.combined, dims, seed, sample), fine, x.reach)
    z = (x - x.mean(axis=0)) / np.maximum(x.std(axis=0), 1e-9)
    if z.shape[1] <= dims:
        return np.asarray(z, dtype=np.float64)
    rng = np.random.default_rng(seed)
    pick = rng.choice(z.shape[0], size=min(z.shape[0], sample), replace=False)
    return np.asarray(z @ principal_axes(z[pick], dims).T)


def build_annotated(
    spec: AnnotatedDatabaseSpec, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop
) -> Arrays:
    """The annotated database arrays of ``spec`` (:class:`schemas.annotations.AnnotatedDatabaseSpec`).

    BLAS runs single-threaded here (:data:`BLAS_THREADS`): the matrices are small, and on a loaded
    machine (workers share the cores) multi-threaded BLAS was 10-40x slower for them."""
    with threadpool_limits(limits=BLAS_THREADS):
        return _build(spec, library, emit, should_stop)


def _build(
    spec: AnnotatedDatabaseSpec, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop
) -> Arrays:
    counts = [m.num_frames for m in library.motions]
    clip_of_frame = np.repeat(np.arange(len(counts), dtype=np.intp), counts)
    emit.progress(0.05, "embedding frames")
    emb, raw, xz, yaw = embed_library(library, spec)
    _check(should_stop)
    z = standardize(emb, SVM_DIMS, spec.seed)
    smooth = int(round(spec.smooth_s * library.fps)) | 1

    def svm_progress(fraction: float, message: str) -> None:
        emit.progress(0.1 + 0.6 * fraction, message)

    prop = propagate(
        z,
        clip_of_frame,
        counts,
        [list(lb) for lb in library.labels],
        c=spec.svm_c,
        gammas=spec.gammas,
        folds=spec.cv_folds,
        max_train_frames=spec.max_train_frames,
        smooth_frames=smooth,
        step=max(1, int(round(spec.predict_step_s * library.fps))),
        exclusive=spec.exclusive,
        switch_cost=spec.switch_s * library.fps,
        self_training=spec.self_training,
        progress=svm_progress,
        should_stop=should_stop,
    )
    _check(should_stop)
    emit.progress(0.72, "continuity features (PCA)")
    feats, mean, comp = pca_features(raw, spec.pca_dims, spec.seed)
    _check(should_stop)

    def cluster_progress(fraction: float, message: str) -> None:
        emit.progress(0.75 + 0.24 * fraction, message)

    clusters = cluster_blocks(
        feats,
        prop.labels,
        counts,
        spec.block_sizes,
        spec.coarse_clusters,
        spec.blocks_per_cluster,
        spec.label_weight,
        spec.seed,
        progress=cluster_progress,
    )
    refs = [c.name or c.bvh or name for c, name in zip(spec.clips, library.names, strict=True)]
    return AnnotatedDatabase(
        clip_refs=np.array(refs, dtype=str),
        vocab=np.array(prop.vocab, dtype=str),
        labels=prop.labels,
        known=prop.known,
        decision=prop.decision,
        report=prop.report_json(),
        features=feats,
        pca_mean=mean,
        pca_components=comp,
        ground_xz=xz,
        ground_yaw=yaw,
        block_sizes=np.array(spec.block_sizes, dtype=np.int64),
        clusters=clusters,
    ).to_arrays()
