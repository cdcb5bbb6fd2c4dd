"""Rhythm couples (:mod:`engines.rhythm.synth`): the follower moves no faster, and turns no faster,
than the example couples, measured by the quality report on the output. On the bundled CMU salsa
couples the pair stands differently in different movements (the follower up to a metre and a half
turn elsewhere relative to the leader); joined in half a beat, that carried the follower at 5-7 m/s
where the examples reach 2.2."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from engines.base import CollectingEmitter, Run
from engines.library import ClipInput
from engines.registry import parse_database_spec
from engines.rhythm.engine import RhythmEngine, music_beats
from engines.rhythm.synth import partner_fade_frames
from motion.samples import sample_path
from schemas.rhythm import RhythmRequest
from tests.engines.rhythm_salsa import COUPLES_SPEC
from workers.execute import build_database_bytes
from workers.store import load_npz

SPEC = COUPLES_SPEC


@lru_cache(maxsize=1)
def couples_engine() -> RhythmEngine:
    """Two bundled salsa couples (leader and follower captured together), built as a build job does."""
    names = {
        "L2": "salsa-leader-02",
        "F2": "salsa-follower-02",
        "L4": "salsa-leader-04",
        "F4": "salsa-follower-04",
    }
    clips = [ClipInput(n, sample_path(s).read_bytes()) for n, s in names.items()]
    data, _ = build_database_bytes(parse_database_spec(SPEC), clips, lambda *_: None, lambda: False)
    engine = RhythmEngine.load(load_npz(data))
    assert isinstance(engine, RhythmEngine)
    return engine


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_follower_moves_no_faster_than_the_examples(seed: int) -> None:
    """At the examples' own tempo, the follower's peak speed, 99th-percentile speed and peak turn
    rate stay within the report's limits (from the example clips), measured on the output."""
    engine = couples_engine()
    bpm = 60.0 / engine.tables.period_s
    req = RhythmRequest.model_validate(
        {"engine": "rhythm", "music": {"bpm": bpm, "duration_s": 12}, "couples": True, "seed": seed}
    )
    out = CollectingEmitter()
    engine.search(req, Run(60.0, emit=out))
    assert out.best is not None and out.best.quality is not None
    plaus = out.best.quality.plausibility
    for name in ("root_speed", "root_speed_p99", "turn_rate"):
        assert plaus[name]["ok"], (name, plaus[name])


def test_partner_joins_fade_at_the_partners_pace() -> None:
    """A partner offset of a metre and a half turn is faded out over seconds, not half a beat; a
    small one over the leader's join; never longer than the movement."""
    t = couples_engine().tables
    short = 0.5 * t.frames_per_beat
    d_root = np.array([[1.0, 0.0, 0.0], [0.01, 0.0, 0.0], [30.0, 0.0, 0.0]])
    d_rot = np.zeros((3, t.partner_rot.shape[2] if t.partner_rot is not None else 1, 3))
    d_rot[0, 0, 1] = np.pi / 2
    frames = partner_fade_frames(t, d_root, d_rot, short)
    assert frames[1] == pytest.approx(short)
    assert frames[0] > 4 * short and frames[2] == pytest.approx(t.frames - 1)


def test_the_follower_is_not_carried_across_the_floor_at_joins() -> None:
    """Faster music than the examples' (100 BPM): no frame moves the follower's root faster than
    its fastest frame in the movements played at that tempo (25 % margin), joins included (the
    follower used to be swept a metre in a third of a second: 10 m/s in one frame)."""
    engine = couples_engine()
    t = engine.tables
    assert t.partner_root is not None
    bpm = 100.0
    req = RhythmRequest.model_validate(
        {"engine": "rhythm", "music": {"bpm": bpm, "duration_s": 30}, "couples": True, "seed": 5}
    )
    _, partners, r = engine.synthesize(req, music_beats(req))
    assert len(r.plans) > 10
    root = partners[0].root_positions[:, [0, 2]]
    step = np.linalg.norm(np.diff(root, axis=0), axis=1) * partners[0].fps  # m/s
    table = np.linalg.norm(np.diff(t.partner_root[..., [0, 2]], axis=1), axis=-1).max() * t.fps
    assert step.max() < 1.25 * table * t.period_s * bpm / 60.0


def test_the_database_dataclass_writes_back_the_stored_arrays() -> None:
    """:class:`engines.rhythm.database.RhythmDatabase` round-trips a couples database (partner
    arrays included) and, once edited, its learned graph too."""
    from engines.rhythm.choreography import edited_arrays
    from engines.rhythm.database import RhythmDatabase
    from schemas.movement_graph import ResolvedEdit
    from tests.engines.database_arrays import assert_same_arrays

    arrays = couples_engine().arrays
    stored = RhythmDatabase.from_arrays(arrays)
    assert stored.partner_root is not None and stored.learned_p is None
    assert_same_arrays(arrays, stored.to_arrays(), "rhythm.")
    p = np.asarray(arrays["rhythm.p"])
    a, b = np.argwhere(p > 0)[0]
    edited = edited_arrays(arrays, [ResolvedEdit(op="weight", source=int(a), target=int(b), weight=5.0)])
    again = RhythmDatabase.from_arrays(edited)
    assert again.learned_p is not None and not np.array_equal(again.p, again.learned_p)
    assert_same_arrays(edited, again.to_arrays(), "rhythm.")
