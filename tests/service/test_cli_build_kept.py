"""``segue build`` of a graph database says what the build kept and left out (and the summary of
``GET /v1/databases/{id}`` holds the same)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from engines.library import library_from_arrays
from motion import Motion
from motion import rotations as rot
from motion.bvh import write_bvh
from motion.mirror import mirror_map
from service.cli import main
from tests.motion.synthetic import walking_biped
from workers.summary import summarize


def arms_up(m: Motion) -> Motion:
    """The same walk with both arms raised sideways: far from every frame of a plain walk."""
    q = m.rotations.copy()
    z = np.array([0.0, 0.0, 1.0])
    q[:, 9] = rot.multiply(q[:, 9], rot.from_axis_angle(z, np.full(m.num_frames, 1.3)))
    q[:, 11] = rot.multiply(q[:, 11], rot.from_axis_angle(z, np.full(m.num_frames, -1.3)))
    return Motion(m.skeleton, m.root_positions, q, m.fps, units="m", name="arms-up")


def test_build_prints_the_kept_component_and_the_summary_holds_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    clips = {
        "walk-a": walking_biped(150, seed=0),
        "walk-b": walking_biped(150, seed=1, heading_deg=90.0),
        "arms-up": arms_up(walking_biped(150, seed=2)),
    }
    for name, m in clips.items():
        write_bvh(m, tmp_path / f"{name}.bvh")
    spec = {"kind": "graph", "clips": [{"bvh": f"{name}.bvh", "units": "m"} for name in clips]}
    (tmp_path / "db.json").write_text(json.dumps(spec), encoding="utf-8")
    assert main(["build", str(tmp_path / "db.json"), "--out", str(tmp_path / "db")]) == 0
    out = capsys.readouterr().out
    assert "graph (all_pairs transitions): kept 2 clips, 300 of 450 frames" in out
    assert "left out 1 clips, 150 frames:" in out
    assert "  arms-up (150 frames): no transition below tau" in out
    stored = json.loads((tmp_path / "db" / "spec.json").read_text(encoding="utf-8"))
    summary = summarize(stored, (tmp_path / "db" / "data.npz").read_bytes(), {})
    assert summary.graph is not None
    assert summary.graph.kept_clips == 2 and summary.graph.kept_frames == 300
    assert summary.graph.moving_frames > 200  # the walks travel
    assert [(d.clip, d.frames) for d in summary.graph.dropped] == [("arms-up", 150)]
    assert summary.graph.dropped_frames == 150 and summary.graph.leaf_edges > 0


def test_mirror_adds_the_mirror_image_of_every_clip(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    clips = {"walk-a": walking_biped(150, seed=0), "walk-b": walking_biped(150, seed=1, heading_deg=90.0)}
    for name, m in clips.items():
        write_bvh(m, tmp_path / f"{name}.bvh")
    spec = {
        "kind": "graph",
        "mirror": True,
        "clips": [{"bvh": f"{name}.bvh", "units": "m"} for name in clips],
    }
    (tmp_path / "db.json").write_text(json.dumps(spec), encoding="utf-8")
    assert main(["build", str(tmp_path / "db.json"), "--out", str(tmp_path / "db"), "-q"]) == 0
    npz = (tmp_path / "db" / "data.npz").read_bytes()
    stored = json.loads((tmp_path / "db" / "spec.json").read_text(encoding="utf-8"))
    summary = summarize(stored, npz, {})
    assert [c.name for c in summary.clips] == ["walk-a", "walk-b", "walk-a (mirror)", "walk-b (mirror)"]
    assert [c.frames for c in summary.clips] == [150] * 4
    with np.load(tmp_path / "db" / "data.npz") as z:
        lib = library_from_arrays(z)
    a, m = lib.motions[0].global_positions(), lib.motions[2].global_positions()
    partner, _ = mirror_map(lib.motions[0].skeleton.names)
    np.testing.assert_allclose(m[:, :, 0], -a[:, partner, 0], atol=1e-9)  # x -> -x, left <-> right
    np.testing.assert_allclose(m[:, :, 1:], a[:, partner, 1:], atol=1e-9)
    assert summary.graph is not None and summary.graph.kept_clips == 4  # the mirrors join the graph
