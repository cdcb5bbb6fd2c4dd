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

from collections.abc import Callable
from typing import overload

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

from motion.ground import body_joints
from schemas.annotations import AnnotatedDatabaseSpec

from ..base import Arrays, Emitter, ShouldStop
from ..library import MIRROR_SUFFIX, MotionLibrary
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
IntArray = npt.NDArray[np.intp]

BLAS_THREADS = 1
"""BLAS threads during a build and a search (small matrices; workers already run in parallel)."""

SVM_DIMS = 48
"""The standardized window embedding is PCA-reduced to at most this many dimensions (speeds up the
SVMs; keeps well over 95% of the variance on Bandai-Namco)."""


def _check(should_stop: ShouldStop) -> None:
    if should_stop():
        raise InterruptedError("build stopped")


def _plan(
    library: MotionLibrary, spec: AnnotatedDatabaseSpec
) -> tuple[IntArray, IntArray, IntArray | None, int]:
    """The SVM joints ``(K,)``, the embedding's frame offsets ``(S,)``, the columns of the fine
    window within it (``None`` unless ``spec.refine_changes`` applies) and ``reach`` (half the
    context window, frames; 0 without refining)."""
    sk = library.motions[0].skeleton
    svm_j = svm_joint_indices(sk, spec.svm_joints)
    offsets = embedding_offsets(
        library.fps, spec.window_s, spec.window_samples, spec.context_s, spec.context_samples
    )
    fine_offsets = window_offsets(library.fps, spec.window_s, spec.window_samples)
    reach = int(round(0.5 * spec.context_s * library.fps))
    if not (bool(spec.refine_changes) and reach > 0 and offsets.size > fine_offsets.size):
        return svm_j, offsets, None, 0
    per = 3 * svm_j.size  # columns are (sample, joint, xyz), samples in the order of offsets
    cols = [i * per + q for i in np.flatnonzero(np.isin(offsets, fine_offsets)) for q in range(per)]
    return svm_j, offsets, np.array(cols, dtype=np.intp), reach


def window_embeddings(library: MotionLibrary, joints: IntArray, offsets: IntArray) -> FloatArray:
    """``(F, S*K*3)`` the window embedding of every database frame (clips end to end, metres;
    :func:`~engines.annotations.features.window_embedding`), filled clip by clip into one array."""
    total = library.total_frames
    out = np.empty((total, offsets.size * joints.size * 3), dtype=np.float64)
    at = 0
    for m in library.motions:
        pos, xz, yaw = clip_frames(m)
        out[at : at + m.num_frames] = window_embedding(pos, xz, yaw, joints, offsets)
        at += m.num_frames
    return out


def continuity_input(library: MotionLibrary) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per database frame: the continuity input ``(F, 3, D)``
    (:func:`~engines.annotations.features.continuity_raw`), ground positions ``(F, 2)`` m and
    headings ``(F,)`` rad, filled clip by clip."""
    body = body_joints(library.motions[0].skeleton)
    total = library.total_frames
    raw: FloatArray | None = None
    xz: FloatArray | None = None
    yaw = np.empty(total, dtype=np.float64)
    at = 0
    for m in library.motions:
        pos, x, y = clip_frames(m)
        s = slice(at, at + m.num_frames)
        part = continuity_raw(pos, x, y, body, m.fps)
        if raw is None or xz is None:
            raw, xz = empty_like_rows(part, total), empty_like_rows(x, total)
        raw[s], xz[s], yaw[s] = part, x, y
        at += m.num_frames
    if raw is None or xz is None:
        raise ValueError("a database needs at least one clip")
    return raw, xz, yaw


def empty_like_rows(part: FloatArray, rows: int) -> FloatArray:
    """An empty array of ``part``'s shape with ``rows`` rows and its memory layout (its axes in
    the same order from slowest to fastest): the layout ``np.concatenate`` gives clips' arrays,
    so reductions over it run in the order they always have and it is stored as it always was
    (the same bits, the same ``.npy`` header)."""
    order = np.argsort(part.strides, kind="stable")[::-1]  # slowest axis first
    shape = (rows, *part.shape[1:])
    return np.empty([shape[a] for a in order], dtype=part.dtype).transpose(np.argsort(order))


def embed_library(
    library: MotionLibrary, spec: AnnotatedDatabaseSpec
) -> tuple[SvmEmbedding, FloatArray, FloatArray, FloatArray]:
    """Per database frame: the SVM window embedding (raw metres; ``combined`` ``(F, E)``, and with
    ``spec.refine_changes`` and a context window also its ``fine`` window columns ``(F, E_f)``,
    ``reach`` half the context window in frames), the continuity input ``(F, 3, D)``, ground
    positions ``(F, 2)`` m and headings ``(F,)`` rad. (A build holds less at once:
    :func:`standardized_embedding` and :func:`continuity_input`.)"""
    svm_j, offsets, cols, reach = _plan(library, spec)
    combined = window_embeddings(library, svm_j, offsets)
    fine = None if cols is None else combined[:, cols]
    raw, xz, yaw = continuity_input(library)
    return SvmEmbedding(combined, fine, reach), raw, xz, yaw


def standardized_embedding(library: MotionLibrary, spec: AnnotatedDatabaseSpec, dims: int) -> SvmEmbedding:
    """``standardize(embed_library(library, spec)[0], dims, spec.seed)`` holding one raw embedding
    ``(F, E)`` at a time (and the fine window's columns): the same numbers
    (:func:`standardize`)."""
    svm_j, offsets, cols, reach = _plan(library, spec)
    combined = window_embeddings(library, svm_j, offsets)
    z = standardize(combined, dims, spec.seed)
    fine = None
    if cols is not None:
        raw_fine = combined[:, cols]  # the fine window's columns, as embed_library takes them
        del combined
        fine = standardize(raw_fine, dims, spec.seed)
    return SvmEmbedding(z, fine, reach)


STANDARDIZE_ROWS = 16_384
"""Rows :func:`standardize` transforms at a time (bounds its working memory past the input)."""


def column_stats(x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``x.mean(axis=0)`` and ``x.std(axis=0)`` of ``x (N, E)``, bit for bit, without the full
    ``(N, E)`` temporary ``x.std`` makes: a C-ordered ``x`` is reduced over rows in order
    (numpy sums a non-contiguous axis row after row), chunk by chunk with the running sum as the
    first row; an F-ordered one column by column (numpy sums a contiguous axis pairwise, as it
    does a single column)."""
    n = x.shape[0]
    if n <= STANDARDIZE_ROWS or x.ndim != 2:
        return np.asarray(x.mean(axis=0)), np.asarray(x.std(axis=0))
    if x.flags.f_contiguous and not x.flags.c_contiguous:
        mean = np.array([x[:, j].mean() for j in range(x.shape[1])])
        std = np.array([x[:, j].std() for j in range(x.shape[1])])
        return mean, std
    x = np.ascontiguousarray(x)

    def row_sum(part: Callable[[slice], FloatArray]) -> FloatArray:
        acc = np.zeros(x.shape[1], dtype=np.float64)
        for a in range(0, n, STANDARDIZE_ROWS):
            acc = np.add.reduce(np.concatenate((acc[None], part(slice(a, a + STANDARDIZE_ROWS)))), axis=0)
        return acc

    mean = row_sum(lambda s: x[s]) / n

    def squared(s: slice) -> FloatArray:
        d: FloatArray = x[s] - mean
        np.multiply(d, d, out=d)
        return d

    return mean, np.sqrt(row_sum(squared) / n)


@overload
def standardize(x: FloatArray, dims: int, seed: int = 0, sample: int = 20_000) -> FloatArray: ...


@overload
def standardize(x: SvmEmbedding, dims: int, seed: int = 0, sample: int = 20_000) -> SvmEmbedding: ...


def standardize(
    x: FloatArray | SvmEmbedding, dims: int, seed: int = 0, sample: int = 20_000
) -> FloatArray | SvmEmbedding:
    """Columns to zero mean and unit variance, then the leading ``dims`` principal components
    (``(F, min(E, dims))``; of each part of an :class:`SvmEmbedding`). Works through the rows
    :data:`STANDARDIZE_ROWS` at a time: memory past ``x`` is the output and a chunk."""
    if isinstance(x, SvmEmbedding):
        fine = None if x.fine is None else standardize(x.fine, dims, seed, sample)
        return SvmEmbedding(standardize(x.combined, dims, seed, sample), fine, x.reach)
    mean, std = column_stats(x)
    scale = np.maximum(std, 1e-9)
    if x.shape[1] <= dims:
        return np.asarray((x - mean) / scale, dtype=np.float64)
    rng = np.random.default_rng(seed)
    pick = rng.choice(x.shape[0], size=min(x.shape[0], sample), replace=False)
    axes = principal_axes((x[pick] - mean) / scale, dims).T
    out = np.empty((x.shape[0], axes.shape[1]), dtype=np.float64)
    for a in range(0, x.shape[0], STANDARDIZE_ROWS):
        b = a + STANDARDIZE_ROWS
        out[a:b] = ((x[a:b] - mean) / scale) @ axes
    return out


def clip_refs(spec: AnnotatedDatabaseSpec, library: MotionLibrary) -> list[str]:
    """Each library clip as the spec names it (its ``name``, else its ``bvh`` reference as
    written); a mirror image (spec ``mirror``, after the clips) as its clip's name plus
    :data:`~engines.library.MIRROR_SUFFIX`."""
    refs = [c.name or c.bvh or name for c, name in zip(spec.clips, library.names, strict=False)]
    if len(library.names) == 2 * len(spec.clips) and spec.mirror:
        refs += [r + MIRROR_SUFFIX for r in refs]
    if len(refs) != len(library.names):
        raise ValueError(f"the spec has {len(spec.clips)} clips, the library {len(library.names)}")
    return refs


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
    emit.progress(0.05, "continuity features (PCA)")
    raw, xz, yaw = continuity_input(library)
    feats, mean, comp = pca_features(raw, spec.pca_dims, spec.seed)
    del raw
    _check(should_stop)
    emit.progress(0.08, "embedding frames")
    z = standardized_embedding(library, spec, SVM_DIMS)
    _check(should_stop)
    smooth = int(round(spec.smooth_s * library.fps)) | 1
    emit.progress(0.1, "propagating labels (SVMs)")

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
    del z
    _check(should_stop)
    emit.progress(0.75, "clustering blocks")

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
    refs = clip_refs(spec, library)
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
