"""Annotation engine end to end on a small slice of real Bandai-Namco data (skips without it): two
walks and two runs, one of each labelled, the others labelled by propagation; a walk-then-run
timeline must come from true walks, then true runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engines.annotations.engine import AnnotationEngine
from engines.base import Run
from engines.library import ClipInput, build_library, library_to_arrays
from motion.metrics import foot_slip
from schemas.annotations import AnnotatedDatabaseSpec, AnnotationRequest
from tests.engines.emitters import Collect

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
D2 = DATA / "bandai-namco" / "dataset-2"

pytestmark = pytest.mark.skipif(not D2.is_dir(), reason=f"shared data not found at {D2}")


def test_walk_then_run_on_real_data() -> None:
    picks = {k: sorted(D2.glob(f"dataset-2_{k}_normal_*.bvh"))[:2] for k in ("walk", "run")}
    raw = [(p.stem, p.read_bytes(), k) for k, ps in picks.items() for p in ps]
    lib0 = build_library([ClipInput(n, b) for n, b, _ in raw], 30.0)
    clips = [
        ClipInput(n, b, None, [{"label": k, "start": 0, "end": m.num_frames}] if i % 2 == 0 else [])
        for i, ((n, b, k), m) in enumerate(zip(raw, lib0.motions, strict=True))
    ]
    lib = build_library(clips, 30.0)
    spec = AnnotatedDatabaseSpec(
        clips=[{"bvh": f"{n}.bvh"} for n, _, _ in raw],
        block_sizes=[16, 8],
        coarse_clusters=20,
        blocks_per_cluster=30,
        gammas=[1.0],
    )
    arrays = AnnotationEngine.build(spec, lib, Collect(), lambda: False)
    arrays.update(library_to_arrays(lib))
    engine = AnnotationEngine(lib, arrays)
    truth = {f"{n}.bvh": k for n, _, k in raw}
    held = [i for i in range(len(raw)) if i % 2]
    for i in held:
        s = engine.db.clip_start[i]
        col = engine.db.vocab.index(raw[i][2])
        assert np.mean(engine.db.labels[s : s + engine.db.counts[i], col] > 0) > 0.8
    req = AnnotationRequest(
        frames=150,
        seed=3,
        timeline=[{"label": "walk", "start": 0, "end": 75}, {"label": "run", "start": 75, "end": 150}],
        footskate=False,
    )
    rec = Collect()
    engine.search(req, Run(0.5, emit=rec))
    best = rec.solutions[-1]
    steady = [i for i in range(150) if abs(i - 75) >= 15]
    ok = [truth[best.provenance[i][0]] == ("walk" if i < 75 else "run") for i in steady]
    assert np.mean(ok) >= 0.95
    assert best.metrics["cut_discontinuity_max_m"] < 0.2
    assert foot_slip(best.motion) < 0.2
