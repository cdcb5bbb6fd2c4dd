"""The rhythm engine (Kim, Park & Shin 2003): music input, movements, groups, graph, synthesis."""

from __future__ import annotations

import struct
from itertools import pairwise
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from engines.base import EngineError, Run
from engines.rhythm.build import dip_agreement, snap_to_speed_minima, speed_dips
from engines.rhythm.engine import RhythmEngine, music_beats
from engines.rhythm.movement_graph import k_medoids, subtractive_clustering, transition_graph
from engines.rhythm.movements import warp_frames
from engines.rhythm.music import MusicError, bpm_beats, parse_midi, write_midi
from engines.rhythm.synth import warp
from schemas.rhythm import RhythmDatabaseSpec, RhythmRequest
from tests.engines.emitters import Collect

from .rhythm_synthetic import library


@pytest.fixture(scope="module")
def synthetic() -> tuple[Any, dict[str, list[float]], RhythmEngine]:
    lib, beats = library()
    spec = RhythmDatabaseSpec.model_validate(
        {
            "kind": "rhythm",
            "clips": [{"bvh": f"{n}.bvh"} for n in lib.names],
            "beats_per_movement": 2,
            "clip_beats": beats,
        }
    )
    arrays = RhythmEngine.build(spec, lib, Collect(), lambda: False)
    return lib, beats, RhythmEngine(lib, arrays)


# -- music ---------------------------------------------------------------------------------------
def test_midi_tempo_change_gives_beat_times() -> None:
    # 4/4: 4 beats at 120 BPM (0.5 s), then 4 at 60 BPM (1 s)
    data = write_midi([(0, 120.0), (4 * 480, 60.0)], end_tick=8 * 480)
    tm = parse_midi(data)
    assert tm.tempos == [(0, 500_000), (1920, 1_000_000)]
    np.testing.assert_allclose(tm.beat_times(), [0, 0.5, 1, 1.5, 2, 3, 4, 5, 6], atol=1e-9)


def test_midi_format1_with_running_status_and_6_8() -> None:
    def track(events: bytes) -> bytes:
        return b"MTrk" + struct.pack(">I", len(events)) + events

    tempo = bytes([0, 0xFF, 0x51, 3]) + (400_000).to_bytes(3, "big")  # 150 BPM quarter
    sig = bytes([0, 0xFF, 0x58, 4, 6, 3, 24, 8])  # 6/8: beat = eighth note
    t0 = track(tempo + sig + bytes([0x83, 0x60, 0xFF, 0x2F, 0]))  # end at tick 480
    notes = bytes([0, 0x90, 60, 100, 0x78, 62, 100, 0x78, 0x80, 60, 0, 0, 0xFF, 0x2F, 0])  # running status
    t1 = track(notes)
    data = b"MThd" + struct.pack(">IHHH", 6, 1, 2, 480) + t0 + t1
    tm = parse_midi(data)
    assert tm.meter() == 6
    np.testing.assert_allclose(tm.beat_times(), [0.0, 0.2, 0.4], atol=1e-9)  # eighths of 0.4 s quarters


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"RIFF0000", "MThd"),
        (
            b"MThd" + struct.pack(">IHHH", 6, 0, 1, 480) + b"MTrk" + struct.pack(">I", 50) + b"\x00\x90",
            "past the end",
        ),
        (
            b"MThd" + struct.pack(">IHHH", 6, 0, 1, 480) + b"MTrk" + struct.pack(">I", 3) + b"\x00\x3c\x40",
            "without a status",
        ),
        (
            b"MThd"
            + struct.pack(">IHHH", 6, 0, 2, 480)
            + b"MTrk"
            + struct.pack(">I", 4)
            + b"\x00\xff\x2f\x00",
            "2 tracks",
        ),
        (
            b"MThd"
            + struct.pack(">IHHH", 6, 0, 1, 480)
            + b"MTrk"
            + struct.pack(">I", 6)
            + b"\x00\xff\x51\x02\x07\xa1",
            "3 data bytes",
        ),
    ],
)
def test_malformed_midi_is_a_clear_error(data: bytes, message: str) -> None:
    with pytest.raises(MusicError, match=message):
        parse_midi(data)


def test_request_music_sources() -> None:
    r = RhythmRequest.model_validate({"music": {"midi": "song.mid"}})
    assert r.input_files() == ["song.mid"]
    r.attach_inputs({"song.mid": write_midi([(0, 120.0)], end_tick=4 * 480)})
    np.testing.assert_allclose(music_beats(r), [0, 0.5, 1, 1.5, 2])
    bad = RhythmRequest.model_validate({"music": {"midi": "x.mid"}})
    bad.attach_inputs({"x.mid": b"nope"})
    with pytest.raises(EngineError, match="MThd"):
        music_beats(bad)
    np.testing.assert_allclose(bpm_beats(120, 2.0), [0, 0.5, 1, 1.5, 2])
    r2 = RhythmRequest.model_validate({"music": {"beats_s": [0.5, 1.0, 1.6]}})
    np.testing.assert_allclose(music_beats(r2), [0.5, 1.0, 1.6])
    cut = RhythmRequest.model_validate({"music": {"beats_s": [0.5, 1.0, 1.6, 2.0], "duration_s": 1.7}})
    np.testing.assert_allclose(music_beats(cut), [0.5, 1.0, 1.6])
    short = RhythmRequest.model_validate({"music": {"beats_s": [0.5, 1.0, 1.6], "duration_s": 0.7}})
    with pytest.raises(EngineError, match="at least 2"):
        music_beats(short)


@pytest.mark.parametrize(
    "music",
    [
        {"bpm": 120},
        {"bpm": 120, "duration_s": 10, "midi": "a.mid"},
        {"beats_s": [1.0, 0.5]},
        {"beats_s": [0.5]},
        {},
    ],
)
def test_music_schema_errors(music: dict[str, Any]) -> None:
    with pytest.raises(ValidationError):
        RhythmRequest.model_validate({"music": music})


def test_spec_and_request_schema_errors() -> None:
    with pytest.raises(ValidationError, match="not a clip"):
        RhythmDatabaseSpec.model_validate(
            {
                "kind": "rhythm",
                "clips": [{"bvh": "60_01.bvh"}],
                "partners": [{"leader": "60_01", "follower": "61_01"}],
            }
        )
    with pytest.raises(ValidationError, match="either"):
        RhythmRequest.model_validate(
            {
                "music": {"bpm": 100, "duration_s": 4},
                "path": [[0, 0], [1, 1]],
                "directions": [{"beat": 0, "heading_deg": 0}],
            }
        )
    with pytest.raises(ValidationError):
        RhythmRequest.model_validate({"music": {"bpm": 100, "duration_s": 4}, "tempo": 3})


# -- time warps ----------------------------------------------------------------------------------
@pytest.mark.parametrize("accent", [0.0, 0.6])
def test_output_warp_puts_motion_beats_on_music_beats(accent: float) -> None:
    beats = np.array([0.0, 0.4, 0.9, 1.3, 2.0, 2.5])
    mv, u = warp(beats, beats, beats_per_movement=2, frames_per_beat=10, accent=accent)
    # at every music beat the movement frame is a beat frame (a multiple of P), of the right movement
    np.testing.assert_allclose(u[:-1], [0, 10, 0, 10, 0], atol=1e-9)
    assert list(mv) == [0, 0, 1, 1, 2, 2]
    assert u[-1] == pytest.approx(10.0)  # the last beat closes the last (partial) movement
    t = np.linspace(0, 2.5, 500)
    mv_t, u_t = warp(beats, t, 2, 10, accent)
    assert np.all(np.diff(mv_t * 100 + u_t) >= -1e-9)  # monotone in time


def test_movement_warp_uses_beats_as_key_times() -> None:
    beats = np.array([0.1, 0.5, 1.1, 1.4, 2.2])
    src = warp_frames(beats, fps=100.0, beats_per_movement=2, frames_per_beat=8)
    assert src.shape == (2, 17)
    np.testing.assert_allclose(src[:, ::8], [[10, 50, 110], [110, 140, 220]], atol=1e-9)
    assert np.all(np.diff(src, axis=1) > 0)


# -- groups and graph ----------------------------------------------------------------------------
def _blobs(sizes: list[int], seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    pts = np.concatenate([rng.normal(10.0 * i, 0.3, (n, 2)) for i, n in enumerate(sizes)])
    truth = np.concatenate([np.full(n, i) for i, n in enumerate(sizes)])
    return ((pts[:, None] - pts[None]) ** 2).sum(-1), truth


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.array_equal(a[:, None] == a[None], b[:, None] == b[None]))


def test_k_medoids_and_subtractive_clustering_find_the_groups() -> None:
    d, truth = _blobs([6, 9, 5])
    assert _same_partition(k_medoids(d, 3, np.random.default_rng(1)), truth)
    labels = subtractive_clustering(d, radius=3.0, squash=1.5, stop_ratio=0.15)
    assert labels.max() + 1 == 3 and _same_partition(labels, truth)


def test_transition_graph_has_no_dead_ends() -> None:
    rng = np.random.default_rng(3)
    labels = np.array([0, 0, 1, 1, 2, 2, 3])
    trans = rng.uniform(1, 5, (7, 7))
    trans[:, 6] = 1e6  # nothing leads well into the last movement...
    trans[6, :] = 1e6  # ...and the last movement leads nowhere well
    g = transition_graph(
        trans, labels, [np.array([0, 2, 4, 6])], kinematic_weight=0.9, threshold=0.3, smoothing=0.0
    )
    assert np.allclose(g.p.sum(axis=1), 1.0)
    assert np.all((g.p > 0).sum(axis=1) >= 1)
    assert g.p[0, 1] > 0 and g.start[0] == 1.0  # the observed 0 -> 1 transition survives
    # behavioural likelihood = observed counts: group 0 went to 1, 1 to 2, 2 to 3
    np.testing.assert_allclose(g.behavioural[:3], np.eye(4)[[1, 2, 3]])


# -- synthesis -----------------------------------------------------------------------------------
def test_synthetic_end_to_end_lands_beats_on_music(synthetic: Any) -> None:
    lib, _, engine = synthetic
    music = [0.3 + 0.45 * k for k in range(13)]
    req = RhythmRequest.model_validate(
        {"music": {"beats_s": music}, "seed": 3, "accent": 0.0, "footskate": False}
    )
    rec = Collect()
    engine.search(req, Run(5.0, emit=rec))
    sol = rec.solutions[-1]
    m = sol.motion
    assert m.num_frames == int(np.floor(music[-1] * 30)) + 1
    assert len(sol.provenance) == m.num_frames
    assert {c for c, _ in sol.provenance} <= set(lib.names)
    # the left arm swings and reverses at every beat: its angle is extreme at every music beat
    angle = 2 * np.arctan2(m.rotations[:, 5, 2], m.rotations[:, 5, 3])
    frames = np.rint(np.array(music) * 30).astype(int)
    # within every beat interval the swing goes one way: the reversals are at the beats...
    for a, b in pairwise(frames):
        lo, hi = sorted((angle[a], angle[b]))
        assert np.all((angle[a : b + 1] >= lo - 0.02) & (angle[a : b + 1] <= hi + 0.02))
    # ...and reverses direction from one beat to the next
    assert np.all(np.sign(angle[frames[1:]]) != np.sign(angle[frames[:-1]]))
    speed = np.abs(np.gradient(angle))
    assert np.median(speed[frames[1:-1]]) < 0.25 * np.median(speed)
    assert sol.annotations["music_beats_s"] == pytest.approx(music)
    assert len(sol.annotations["movements"]) == 6  # 12 beat intervals, 2 beats per movement
    assert sol.quality is not None and sol.quality.metrics["beat_align_bailando"] > 0.5
    assert sol.constraint_errors["music"]["satisfied"]


def test_directions_steer_and_crowd_avoids(synthetic: Any) -> None:
    _, _, engine = synthetic
    req = RhythmRequest.model_validate(
        {
            "music": {"bpm": 120, "duration_s": 8},
            "characters": 4,
            "spacing_m": 0.5,
            "directions": [{"beat": 0, "heading_deg": 90, "speed": 0.4}],
            "footskate": False,
        }
    )
    leaders, partners, _ = engine.synthesize(req, music_beats(req))
    assert len(leaders) == 4 and not partners
    start = np.array([m.root_positions[0, [0, 2]] for m in leaders])
    end = np.array([m.root_positions[-1, [0, 2]] for m in leaders])
    travel = end - start
    assert np.all(travel[:, 0] > 0.5)  # moved towards +X
    gaps = np.linalg.norm(end[:, None] - end[None], axis=-1)[np.triu_indices(4, 1)]
    assert gaps.min() > 0.2
    rec = Collect()
    engine.search(req, Run(5.0, emit=rec))
    combined = rec.solutions[-1].motion
    assert combined.num_joints == 1 + 4 * leaders[0].num_joints
    assert combined.skeleton.names[1].startswith("c0_")


def test_couples_need_partners(synthetic: Any) -> None:
    _, _, engine = synthetic
    req = RhythmRequest.model_validate({"music": {"bpm": 120, "duration_s": 4}, "couples": True})
    with pytest.raises(EngineError, match="partners"):
        engine.search(req, Run(1.0, emit=Collect()))


def test_couples_move_together() -> None:
    lib, beats = library(count=4)
    spec = RhythmDatabaseSpec.model_validate(
        {
            "kind": "rhythm",
            "clips": [{"bvh": f"{n}.bvh"} for n in lib.names],
            "beats_per_movement": 2,
            "clip_beats": beats,
            "partners": [
                {"leader": "dance0", "follower": "dance1"},
                {"leader": "dance2", "follower": "dance3"},
            ],
        }
    )
    engine = RhythmEngine(lib, RhythmEngine.build(spec, lib, Collect(), lambda: False))
    req = RhythmRequest.model_validate(
        {"music": {"bpm": 100, "duration_s": 6}, "couples": True, "characters": 2, "footskate": False}
    )
    leaders, partners, _ = engine.synthesize(req, music_beats(req))
    assert len(partners) == 2
    for lead, follow in zip(leaders, partners, strict=True):
        # the follower stays where the pair's example put it relative to the leader (the examples
        # were captured side by side at the origin, so the pair stays close)
        gap = np.linalg.norm(lead.root_positions[:, [0, 2]] - follow.root_positions[:, [0, 2]], axis=1)
        assert gap.max() < 2.0


def test_beats_snap_onto_speed_dips() -> None:
    speed = 1.0 + np.cos(2 * np.pi * np.arange(300) / 50.0)  # dips every 50 frames from frame 25
    dips = speed_dips(speed, fps=100.0)
    np.testing.assert_allclose(dips, [0.25, 0.75, 1.25, 1.75, 2.25, 2.75], atol=0.011)
    snapped = snap_to_speed_minima(np.array([0.22, 0.8, 1.0, 1.74]), dips, window_s=0.1)
    np.testing.assert_allclose(snapped, [dips[0], dips[1], 1.0, dips[3]])  # 1.0 has no dip within 0.1 s
    assert dip_agreement(snapped[[0, 1, 3]], dips) == pytest.approx(1.0)
    assert dip_agreement(np.array([0.5, 1.0]), dips) < 0.01


def test_mirror_doubles_the_examples(synthetic: Any) -> None:
    lib, beats, engine = synthetic
    spec = RhythmDatabaseSpec.model_validate(
        {
            "kind": "rhythm",
            "clips": [{"bvh": f"{n}.bvh"} for n in lib.names],
            "beats_per_movement": 2,
            "clip_beats": beats,
            "mirror": True,
        }
    )
    arrays = RhythmEngine.build(spec, lib, Collect(), lambda: False)
    assert arrays["rhythm.root"].shape[0] == 2 * engine.tables.root.shape[0]


def test_build_errors(synthetic: Any) -> None:
    lib, beats, _ = synthetic
    spec = RhythmDatabaseSpec.model_validate(
        {
            "kind": "rhythm",
            "clips": [{"bvh": f"{n}.bvh"} for n in lib.names],
            "beats_per_movement": 16,
            "clip_beats": {n: b[:5] for n, b in beats.items()},
        }
    )
    with pytest.raises(EngineError, match="16"):
        RhythmEngine.build(spec, lib, Collect(), lambda: False)


def test_path_in_formation_keeps_rows(synthetic: Any) -> None:
    _, _, engine = synthetic
    req = RhythmRequest.model_validate(
        {
            "music": {"bpm": 120, "duration_s": 10},
            "characters": 3,
            "formation": "line",
            "spacing_m": 1.0,
            "path": [[0, 0], [0, 3], [0, 3], [3, 6], [3, 6]],  # repeated points are skipped
            "speed": 0.4,
            "footskate": False,
        }
    )
    leaders, _, _ = engine.synthesize(req, music_beats(req))
    start = np.array([m.root_positions[0, [0, 2]] for m in leaders])
    end = np.array([m.root_positions[-1, [0, 2]] for m in leaders])
    np.testing.assert_allclose(start[:, 0], [-1.0, 0.0, 1.0], atol=0.05)
    assert np.all(end[:, 1] - start[:, 1] > 1.5)  # marched along the path
    # the rows keep their order across the path (offset curves do not cross)
    assert np.all(np.diff(end[:, 0]) > 0.3)


def test_the_database_dataclass_writes_back_the_stored_arrays(synthetic: Any) -> None:
    """:class:`engines.rhythm.database.RhythmDatabase`: ``to_arrays`` of what ``from_arrays`` read
    is the stored arrays; without beat keys (older databases) synthesis gets the nominal beats."""
    from engines.rhythm.database import RhythmDatabase
    from tests.engines.database_arrays import assert_same_arrays

    _, _, engine = synthetic
    stored = RhythmDatabase.from_arrays(engine.arrays)
    assert stored.beat_keys is not None and stored.partner_root is None
    assert_same_arrays(engine.arrays, stored.to_arrays(), "rhythm.")
    older = {k: v for k, v in engine.arrays.items() if k not in ("rhythm.beat_keys", "rhythm.clarity")}
    tables = RhythmDatabase.from_arrays(older).tables()
    p, b = tables.frames_per_beat, tables.beats_per_movement
    assert np.array_equal(tables.beat_keys[0], np.arange(b + 1) * p)
    assert np.array_equal(tables.clarity, np.ones(tables.labels.size))
