"""The build's SVM embedding: the fine window's columns kept apart for refining label changes."""

from __future__ import annotations

import numpy as np
import pytest

from engines.annotations.blocks import block_embedding, block_starts, cluster_blocks, two_stage_kmeans
from engines.annotations.build import embed_library, standardize
from engines.annotations.features import (
    clip_frames,
    svm_joint_indices,
    window_embedding,
    window_offsets,
)
from engines.annotations.propagate import SvmEmbedding
from engines.library import MotionLibrary
from schemas.annotations import AnnotatedDatabaseSpec
from tests.engines.graph_synthetic import arc_biped


def _library() -> MotionLibrary:
    motions = (arc_biped(70, 0.7, 0.0, seed=1), arc_biped(50, 1.7, 0.0, seed=2))
    return MotionLibrary(("a", "b"), motions, ((), ()))


def _spec(**kw: object) -> AnnotatedDatabaseSpec:
    return AnnotatedDatabaseSpec(clips=[{"bvh": "a.bvh"}, {"bvh": "b.bvh"}], **kw)


def test_embedding_keeps_the_fine_window_apart() -> None:
    lib = _library()
    spec = _spec()
    assert spec.refine_changes
    emb, _, _, _ = embed_library(lib, spec)
    assert isinstance(emb, SvmEmbedding) and emb.fine is not None
    assert emb.reach == round(0.5 * spec.context_s * lib.fps)
    # the fine part is the fine window's embedding alone, frame for frame
    sk = lib.motions[0].skeleton
    joints = svm_joint_indices(sk)
    offsets = window_offsets(lib.fps, spec.window_s, spec.window_samples)
    want = np.concatenate([window_embedding(*clip_frames(m), joints, offsets) for m in lib.motions])
    np.testing.assert_allclose(emb.fine, want)
    assert emb.combined.shape[1] > emb.fine.shape[1]
    z = standardize(emb, 16)
    assert isinstance(z, SvmEmbedding) and z.reach == emb.reach
    assert z.combined.shape == (120, 16) and z.fine is not None and z.fine.shape == (120, 16)
    np.testing.assert_allclose(z.combined, standardize(emb.combined, 16))


def test_no_fine_window_without_refining_or_context() -> None:
    lib = _library()
    for spec in (_spec(refine_changes=False), _spec(context_s=0.0)):
        emb, _, _, _ = embed_library(lib, spec)
        assert emb.fine is None and emb.reach == 0


def test_large_finer_levels_cluster_in_two_stages_of_similar_blocks() -> None:
    rng = np.random.default_rng(0)
    # two far-apart kinds of motion, 1500 frames each, in one clip
    feats = np.concatenate((rng.normal(0, 1, (1500, 6)), rng.normal(40, 1, (1500, 6)))).astype(np.float32)
    labels = np.ones((3000, 1), dtype=np.int8)
    flat = cluster_blocks(feats, labels, [3000], [16, 8], 4, 20, max_flat=10_000)
    staged = cluster_blocks(feats, labels, [3000], [16, 8], 4, 20, max_flat=32)
    np.testing.assert_array_equal(flat[16], staged[16])  # the top level is never staged
    starts = block_starts([3000], 8)
    emb = block_embedding(feats, labels, starts, 8, 1.0)
    np.testing.assert_array_equal(staged[8][starts], two_stage_kmeans(emb, 150, 20))
    cl = two_stage_kmeans(emb, 150, 20, cell_clusters=16)  # 10 cells of about 15 clusters
    assert not np.array_equal(cl, flat[8][starts])
    sizes = np.bincount(cl)
    assert sizes.min() > 0  # dense ids
    assert 12 < starts.size / sizes.size < 30  # about blocks_per_cluster blocks each
    kind = starts + 4 >= 1500
    mixed = [c for c in range(sizes.size) if 0 < kind[cl == c].mean() < 1]
    assert len(mixed) <= 1  # only blocks straddling the change of kind may share a cluster
    with pytest.raises(ValueError, match="no blocks"):
        two_stage_kmeans(emb[:0], 4, 20)
