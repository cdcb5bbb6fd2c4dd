"""A small rhythm database of the bundled CMU salsa leaders (real motion capture), built in-process
once per test session the way a build job builds it: five dances at 30 fps, 4 beats per movement,
and an edge threshold that leaves the learned movement graph sparse (so edits have transitions to
add as well as to cut)."""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np

from engines.library import ClipInput
from engines.registry import parse_database_spec
from engines.rhythm.engine import RhythmEngine
from motion.samples import sample_path
from workers.execute import build_database_bytes
from workers.store import load_npz

SAMPLES = ("salsa-leader", "salsa-leader-02", "salsa-leader-04", "salsa-leader-05", "salsa-leader-12")

SPEC: dict[str, Any] = {
    "kind": "rhythm",
    "clips": [{"bvh": f"sample:{n}"} for n in SAMPLES],
    "fps": 30,
    "beats_per_movement": 4,
    "edge_threshold": 0.08,
}

COUPLES_SPEC: dict[str, Any] = {
    "kind": "rhythm",
    "clips": [
        {"bvh": "sample:salsa-leader-02", "name": "L2"},
        {"bvh": "sample:salsa-follower-02", "name": "F2"},
        {"bvh": "sample:salsa-leader-04", "name": "L4"},
        {"bvh": "sample:salsa-follower-04", "name": "F4"},
    ],
    "partners": [{"leader": "L2", "follower": "F2"}, {"leader": "L4", "follower": "F4"}],
    "beats_per_movement": 4,
}
"""Two bundled salsa couples (leader and follower captured together) as a rhythm database spec."""


@lru_cache(maxsize=1)
def salsa_npz() -> bytes:
    """The built database's ``data.npz`` bytes; clips named as the samples."""
    clips = [ClipInput(n, sample_path(n).read_bytes()) for n in SAMPLES]
    data, _ = build_database_bytes(parse_database_spec(SPEC), clips, lambda *_: None, lambda: False)
    return data


def salsa_arrays() -> dict[str, Any]:
    """A fresh copy of the database's arrays."""
    return load_npz(salsa_npz())


def group_walks(
    arrays: dict[str, Any], seeds: range, bpm: float = 80.0, duration_s: float = 30.0
) -> list[list[int]]:
    """The group sequence synthesis walks for each seed (one dancer, free dancing): what the
    engine's ``search`` reports as ``annotations.movements[*].group``. At 80 BPM, slower than the
    salsa examples (about 87), the tempo allows every movement; faster music avoids the movements
    too fast for it (:func:`engines.rhythm.synth.too_fast`)."""
    from engines.rhythm.engine import music_beats
    from schemas.rhythm import RhythmRequest

    engine = RhythmEngine.load(arrays)
    assert isinstance(engine, RhythmEngine)
    walks = []
    for seed in seeds:
        req = RhythmRequest.model_validate(
            {"engine": "rhythm", "music": {"bpm": bpm, "duration_s": duration_s}, "seed": seed}
        )
        _, _, r = engine.synthesize(req, music_beats(req))
        walks.append([int(p["group"]) for p in r.plans])
    return walks


def transition_counts(walks: list[list[int]], k: int) -> np.ndarray:
    """``(K, K)`` how often each transition was taken over all walks."""
    counts = np.zeros((k, k), dtype=np.int64)
    for w in walks:
        np.add.at(counts, (np.asarray(w[:-1]), np.asarray(w[1:])), 1)
    return counts
