"""Annotated databases with ``mirror``: every clip's mirror image, its labels' sides exchanged,
addressed by name in label queries, frame constraints and corrections."""

from __future__ import annotations

import numpy as np
import pytest

from engines.annotations.corrections import apply_corrections
from engines.annotations.engine import AnnotationEngine
from engines.annotations.labels import LabelTable
from engines.base import CollectingEmitter, EngineError, Run
from engines.library import MotionLibrary, library_to_arrays, with_mirrors
from motion.mirror import mirror_map
from schemas.annotations import AnnotatedDatabaseSpec, AnnotationRequest, LabelCorrection
from tests.engines.graph_synthetic import arc_biped


def _spec(**kw: object) -> AnnotatedDatabaseSpec:
    clips = [
        {"bvh": "a.bvh", "name": "a", "labels": [{"label": "turn-left", "start": 0, "end": 90}]},
        {"bvh": "b.bvh", "name": "b", "labels": [{"label": "walk", "start": 0, "end": 90}]},
    ]
    return AnnotatedDatabaseSpec(clips=clips, gammas=[1.0], coarse_clusters=8, **kw)


def _engine(spec: AnnotatedDatabaseSpec) -> tuple[AnnotationEngine, MotionLibrary]:
    lib = MotionLibrary(
        ("a", "b"),
        (arc_biped(90, 1.2, 40.0, seed=1), arc_biped(90, 1.2, 0.0, seed=2)),
        tuple(tuple(c.model_dump()["labels"]) for c in spec.clips),
    )
    lib = AnnotationEngine.library_for(spec, lib)
    arrays = AnnotationEngine.build(spec, lib, CollectingEmitter(), lambda: False)
    arrays.update(library_to_arrays(lib))
    return AnnotationEngine(lib, arrays), lib


@pytest.fixture(scope="module")
def mirrored() -> tuple[AnnotationEngine, MotionLibrary]:
    return _engine(_spec(mirror=True))


def test_mirror_images_follow_their_clips_with_sides_exchanged(
    mirrored: tuple[AnnotationEngine, MotionLibrary],
) -> None:
    engine, lib = mirrored
    assert lib.names == ("a", "b", "a (mirror)", "b (mirror)")
    a, m = lib.motions[0].global_positions(), lib.motions[2].global_positions()
    partner, _ = mirror_map(lib.motions[0].skeleton.names)
    np.testing.assert_allclose(m[:, :, 0], -a[:, partner, 0], atol=1e-9)  # x -> -x, left <-> right
    table = LabelTable.read(engine.arrays)
    assert table.refs == ("a", "b", "a (mirror)", "b (mirror)")
    assert sorted(table.vocab) == ["turn-left", "turn-right", "walk"]
    col = {lab: j for j, lab in enumerate(table.vocab)}
    a_rows = slice(0, 90)
    mirror_rows = slice(int(table.clip_start[2]), int(table.clip_start[2]) + 90)
    assert np.all(table.labels[a_rows, col["turn-left"]] == 1)
    assert np.all(table.labels[mirror_rows, col["turn-right"]] == 1)  # the mirror turns right
    assert np.all(table.labels[mirror_rows, col["turn-left"]] == -1)
    b_mirror = slice(int(table.clip_start[3]), int(table.clip_start[3]) + 90)
    assert np.all(table.labels[b_mirror, col["walk"]] == 1)  # no side: the same label
    ranges = AnnotationEngine.clip_labels(engine.arrays, "a (mirror)").labels
    assert {(r.label, r.start, r.end, r.value) for r in ranges if r.value == 1} == {("turn-right", 0, 90, 1)}


def test_a_frame_constraint_names_a_mirror_image(mirrored: tuple[AnnotationEngine, MotionLibrary]) -> None:
    engine, _ = mirrored
    request = AnnotationRequest(
        frames=60,
        timeline=[{"label": "turn-right", "start": 0, "end": 60}],
        frame_constraints=[{"frame": 30, "clip": "b (mirror)", "clip_frame": 40}],
        passes=2,
        seed=1,
    )
    run = Run(60.0)
    engine.search(request, run)
    best = run.emit.solutions[-1]  # type: ignore[attr-defined]
    assert best.provenance[30] == ("b (mirror)", 40)
    assert any(clip == "a (mirror)" for clip, _ in best.provenance)  # the right turns are the mirror's


def test_a_correction_on_a_mirror_image_corrects_its_clip_mirrored(
    mirrored: tuple[AnnotationEngine, MotionLibrary],
) -> None:
    engine, _ = mirrored
    spec = _spec(mirror=True)
    fixes = [LabelCorrection(clip="a (mirror)", start=10, end=20, label="turn-right", value=-1)]
    new = apply_corrections(spec, fixes)
    assert new.mirror
    a = new.clips[0].model_dump()["labels"]
    assert {"label": "turn-left", "start": 10, "end": 20, "value": -1} in a
    accepted = apply_corrections(
        spec,
        [LabelCorrection(clip="b (mirror)", start=0, end=5, action="accept")],
        LabelTable.read(engine.arrays),
    )
    b = {(lb["label"], lb["value"]) for lb in accepted.clips[1].model_dump()["labels"]}
    assert {("walk", 1), ("turn-left", -1), ("turn-right", -1)} <= b
    with pytest.raises(EngineError, match="c \\(mirror\\)"):
        apply_corrections(spec, [LabelCorrection(clip="c (mirror)", start=0, end=5, label="walk")])
    with pytest.raises(EngineError, match="a \\(mirror\\)"):  # no mirror images without 'mirror'
        apply_corrections(_spec(), [LabelCorrection(clip="a (mirror)", start=0, end=5, label="walk")])


def test_without_mirror_the_library_is_as_read() -> None:
    spec = _spec()
    lib = MotionLibrary(("a", "b"), (arc_biped(40, 1.0, 0.0), arc_biped(40, 1.0, 0.0, seed=3)), ((), ()))
    assert AnnotationEngine.library_for(spec, lib) is lib
    assert AnnotationEngine.library_frames(spec, 80) == 80
    assert AnnotationEngine.library_frames(_spec(mirror=True), 80) == 160


def test_with_mirrors_exchanges_the_sides_labels_name() -> None:
    lib = MotionLibrary(
        ("x",),
        (arc_biped(30, 1.0, 0.0),),
        (
            (
                {"label": "wave-left-hand", "start": 0, "end": 10, "value": 1},
                {"label": "walk", "start": 0, "end": 30},
            ),
        ),
    )
    both = with_mirrors(lib)
    assert both.labels[0] == lib.labels[0]
    assert both.labels[1] == (
        {"label": "wave-right-hand", "start": 0, "end": 10, "value": 1},
        {"label": "walk", "start": 0, "end": 30},
    )
