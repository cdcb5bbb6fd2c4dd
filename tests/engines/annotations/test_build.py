"""The build's SVM embedding: the fine window's columns kept apart for refining label changes."""

from __future__ import annotations

import numpy as np

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
