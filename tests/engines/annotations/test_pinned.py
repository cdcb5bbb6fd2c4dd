"""Annotation outputs from Bandai-Namco libraries holding clips whose ``joint_Root`` moves
(``dataset-1`` ``dash_001``, ``run_001``, ``walk-back_001``, ``walk_002``): those clips are
pinned to the usual reference pose, so joint 0 never moves and the body never swings about it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engines.annotations.engine import AnnotationEngine
from engines.base import CollectingEmitter, Run
from engines.library import ClipInput, build_library
from engines.registry import parse_database_spec
from schemas.annotations import AnnotationRequest

DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "bandai-namco"
CLIPS = (
    ("dataset-1/dataset-1_walk_normal_001.bvh", "walk"),
    ("dataset-1/dataset-1_walk_active_001.bvh", "walk"),
    ("dataset-1/dataset-1_walk_normal_002.bvh", "walk"),  # joint_Root moves
    ("dataset-1/dataset-1_walk-back_normal_001.bvh", "walk-back"),  # joint_Root moves
    ("dataset-1/dataset-1_walk-back_active_001.bvh", "walk-back"),
)
pytestmark = pytest.mark.skipif(not DATA.exists(), reason=f"shared data not found ({DATA})")


def test_clips_that_move_joint_zero_are_played_pinned() -> None:
    raw = [(Path(rel).stem, (DATA / rel).read_bytes(), label) for rel, label in CLIPS]
    counts = [m.num_frames for m in build_library([ClipInput(n, b) for n, b, _ in raw], 30.0).motions]
    clips = [
        ClipInput(n, b, None, [{"label": label, "start": 0, "end": k}])
        for (n, b, label), k in zip(raw, counts, strict=True)
    ]
    spec = parse_database_spec({"kind": "annotated", "clips": [{"bvh": c.name} for c in clips]})
    arrays, lib = AnnotationEngine.build_database(spec, clips, CollectingEmitter(), lambda: False)  # type: ignore[arg-type]
    engine = AnnotationEngine(lib, arrays)
    static = engine.frames.static
    assert static is not None  # the usual pose of joint_Root, though two clips move it
    request = AnnotationRequest(
        frames=120,
        timeline=[{"label": "walk", "start": 0, "end": 50}, {"label": "walk-back", "start": 70, "end": 120}],
        frame_constraints=[
            {"frame": 20, "clip": "dataset-1_walk_normal_002", "clip_frame": 15},
            {"frame": 95, "clip": "dataset-1_walk-back_normal_001", "clip_frame": 30},
        ],
        passes=4,
        seed=2,
    )
    run = Run(120.0)
    engine.search(request, run)
    best = run.emit.solutions[-1]  # type: ignore[attr-defined]
    played = {clip for clip, _ in best.provenance}
    assert {"dataset-1_walk_normal_002", "dataset-1_walk-back_normal_001"} <= played
    motion = best.motion
    np.testing.assert_allclose(motion.root_positions, np.broadcast_to(static[0], motion.root_positions.shape))
    assert best.quality is not None
    assert best.quality.plausibility["joint_step"]["ok"], best.quality.plausibility["joint_step"]
    assert best.quality.plausibility["joint_step"]["joint"] != "joint_Root"
    for name in ("frame[0]", "frame[1]"):
        assert best.quality.constraint_errors[name]["pose_cm"] < 25.0  # the body's pose, not joint_Root's
