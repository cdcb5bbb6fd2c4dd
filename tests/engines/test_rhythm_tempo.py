"""Music faster than the examples: movements whose floor speed the tempo would push past the
examples' are avoided (:func:`engines.rhythm.synth.too_fast`), on real salsa (bundled leaders)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from engines.base import Run
from engines.registry import parse_job_request
from engines.rhythm.engine import RhythmEngine
from engines.rhythm.synth import beat_rates, too_fast
from tests.engines.rhythm_salsa import salsa_arrays
from tests.engines.test_quality_engines import Collect, best


@pytest.fixture(scope="module")
def engine() -> RhythmEngine:
    eng = RhythmEngine.load(salsa_arrays())
    assert isinstance(eng, RhythmEngine)
    return eng


def test_beat_rates_scale_with_the_tempo(engine: RhythmEngine) -> None:
    t, limits = engine.tables, engine.speed_limits
    rates = beat_rates(t)
    assert rates.shape == (t.root.shape[0], 2) and (rates > 0).all()
    slow, fast = too_fast(rates, 2.0, limits, t.period_s), too_fast(rates, 0.3, limits, t.period_s)
    assert not slow.any() and fast.sum() > 0  # faster music rules out more movements, never fewer
    assert (fast | ~too_fast(rates, 0.5, limits, t.period_s)).all()
    assert not too_fast(rates, t.period_s, limits, t.period_s).any()  # at their own tempo: never
    # a quarter beat's travel at a period of 1 s is its speed in m/s: the same as measuring it
    q = t.frames_per_beat // 4
    m = int(np.argmax(rates[:, 0]))
    xz = t.root[m, :, [0, 2]].T
    travel = np.linalg.norm(xz[q:] - xz[:-q], axis=1).max()
    assert rates[m, 0] == pytest.approx(travel * t.frames_per_beat / q)


def _dance(engine: RhythmEngine, bpm: float, seed: int) -> Any:
    req = parse_job_request({"engine": "rhythm", "music": {"bpm": bpm, "duration_s": 20}, "seed": seed})
    out = Collect()
    engine.search(req, Run(10.0, emit=out))
    return best(out)


@pytest.mark.parametrize("seed", [1, 2])
def test_faster_music_keeps_the_body_within_the_examples(engine: RhythmEngine, seed: int) -> None:
    """At 1.2 times the examples' tempo (a third of the movements too fast for it) no such movement
    is danced, and the report (measured on the output) finds the floor speed within the examples'."""
    t = engine.tables
    fast = too_fast(beat_rates(t), t.period_s / 1.2, engine.speed_limits, t.period_s)
    assert 0 < fast.mean() < 1, "the test needs movements the tempo rules out and others"
    sol = _dance(engine, 1.2 * 60 / t.period_s, seed)
    danced = [m for mv in sol.annotations["movements"] for m in mv["members"]]
    assert not fast[danced].any()
    q = sol.quality
    assert q is not None
    for key in ("root_speed", "root_speed_p99"):
        assert q.plausibility[key]["ok"], q.reasons


def test_where_the_graph_leaves_no_choice_a_fast_movement_is_rare(engine: RhythmEngine) -> None:
    """At 1.4 times the tempo two thirds of the movements are too fast; a dancer whose next groups
    are all too fast still goes on (they count 1 %), so a few are danced, far fewer than their share."""
    t = engine.tables
    fast = too_fast(beat_rates(t), t.period_s / 1.4, engine.speed_limits, t.period_s)
    danced = [
        m
        for seed in (1, 2, 3, 4)
        for mv in _dance(engine, 1.4 * 60 / t.period_s, seed).annotations["movements"]
        for m in mv["members"]
    ]
    assert fast.mean() > 0.5 and fast[danced].mean() < 0.25
