"""The live control session (:mod:`engines.control.session`): fixed latency, whole output, errors."""

from __future__ import annotations

import numpy as np
import pytest

from engines.base import EngineError
from engines.control.engine import ControlEngine
from engines.library import ClipInput, build_library, library_to_arrays
from engines.registry import parse_database_spec
from motion.bvh import bvh_text
from motion.ground import ground_frames
from tests.engines.emitters import Collect
from tests.engines.test_control import walk_engine
from tests.motion.synthetic import walking_biped


def pair_engine() -> ControlEngine:
    """A dance-like database: each leader walk drives a follower walking beside it."""
    clips, pairs = [], []
    for i in range(3):
        lead = walking_biped(240, speed=1.0 + 0.2 * i, heading_deg=40.0 * i, seed=i)
        follow = walking_biped(240, speed=1.0 + 0.2 * i, heading_deg=40.0 * i, seed=10 + i)
        clips.append(ClipInput(f"lead{i}", bvh_text(lead).encode()))
        clips.append(ClipInput(f"follow{i}", bvh_text(follow).encode()))
        pairs.append({"control": f"lead{i}", "target": f"follow{i}"})
    spec = parse_database_spec(
        {
            "kind": "control",
            "pairs": pairs,
            "clips": [{"bvh": f"{c.name}.bvh", "name": c.name} for c in clips],
            "segmentation": {"method": "fixed", "seconds": 0.5},
        }
    )
    library = build_library(clips, spec.fps)
    arrays = ControlEngine.build(spec, library, Collect(), lambda: False)
    arrays.update(library_to_arrays(library))
    return ControlEngine(library, arrays)


def stream(session, frames: np.ndarray, chunk: int) -> tuple[np.ndarray, list[int]]:  # type: ignore[no-untyped-def]
    """Push ``frames`` ``chunk`` at a time, then finish; the roots sent and, after every push, how many
    target frames had been sent."""
    roots, sent = [], []
    for i in range(0, frames.shape[0], chunk):
        msg = session.push(frames[i : i + chunk])
        assert msg["start"] == sum(len(r) for r in roots)
        roots.append(np.asarray(msg["root"]).reshape(-1, 3))
        sent.append(session.frame)
    msg = session.finish()
    roots.append(np.asarray(msg["root"]).reshape(-1, 3))
    return np.concatenate(roots), sent


def test_a_streamed_path_is_walked_with_the_stated_latency() -> None:
    engine = walk_engine()
    held = walking_biped(210, speed=1.1, heading_deg=-30.0, seed=9)
    path, _ = ground_frames(held)
    session = engine.live_control(latency_s=1.0)
    hello = session.hello_message()
    assert hello["control"] == "path" and hello["latency_frames"] == 30 and hello["fps"] == 30.0
    root, sent = stream(session, path, 5)
    assert root.shape == (210, 3)
    received = np.minimum(np.arange(1, len(sent) + 1) * 5, 210)
    # never later than the latency (once the first window could be solved), never earlier
    assert all(s <= max(0, r - 30) for s, r in zip(sent, received, strict=True))
    assert all(s == r - 30 for s, r in zip(sent, received, strict=True) if r >= 90)
    rms = float(np.sqrt(((root[:, [0, 2]] - path) ** 2).sum(-1).mean()))
    assert rms < 0.15 and session.solves >= 3


def test_a_streamed_leader_drives_the_follower() -> None:
    engine = pair_engine()
    leader = walking_biped(180, speed=1.1, heading_deg=20.0, seed=7)
    joints = list(engine.db.meta["control_joints"])
    pos = leader.global_positions() * leader.metres_per_unit
    cloud = pos[:, [leader.skeleton.names.index(j) for j in joints]]
    session = engine.live_control(latency_s=1.2)
    assert session.hello_message()["control_joints"] == joints
    root, sent = stream(session, cloud, 7)
    assert root.shape == (180, 3) and sent[-1] == 180 - 36
    # the follower walks beside the leader: its hips stay within a stride of the leader's
    assert float(np.linalg.norm(root[:, [0, 2]] - pos[:, 0, [0, 2]], axis=-1).mean()) < 1.0


def test_bad_frames_and_settings_are_refused() -> None:
    engine = walk_engine()
    with pytest.raises(EngineError, match="latency_s"):
        engine.live_control(latency_s=0.1)
    session = engine.live_control()
    with pytest.raises(EngineError, match=r"\[x, z\]"):
        session.push(np.zeros((3, 4, 3)))
    with pytest.raises(EngineError, match="finite"):
        session.push(np.full((2, 2), np.nan))
    assert session.finish()["root"] == []  # nothing received, nothing to send


def test_opening_a_session_loads_the_solver_and_leaves_it_fresh(monkeypatch: pytest.MonkeyPatch) -> None:
    """The session solves one window of the database's own control while it opens (the compiled
    kernels load then, not when the first frames are due) and keeps nothing of it."""
    engine = pair_engine()
    solved: list[int] = []
    original = engine.live_control().__class__._solve

    def counting(self, window):  # type: ignore[no-untyped-def]
        solved.append(int(window.shape[0]))
        return original(self, window)

    monkeypatch.setattr(engine.live_control().__class__, "_solve", counting)
    session = engine.live_control(latency_s=1.0)
    assert len(solved) == 1 and solved[0] >= session.min_window
    assert session.received == 0 and session.frame == 0 and session.solves == 0 and not session.plan.rows
