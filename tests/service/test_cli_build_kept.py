"""``segue build`` of a graph database says what the build kept and left out (and the summary of
``GET /v1/databases/{id}`` holds the same)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from engines.library import library_from_arrays
from motion import Motion
from motion import rotations as rot
from motion.bvh import write_bvh
from motion.mirror import mirror_map
from schemas.databases import DatabaseSummary
from service.cli import main
from service.cli.jobs import kept_lines
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
    assert "left out 1 clip, 150 frames:" in out
    assert "  arms-up (150 frames): no transition below tau" in out
    stored = json.loads((tmp_path / "db" / "spec.json").read_text(encoding="utf-8"))
    summary = summarize(stored, (tmp_path / "db" / "data.npz").read_bytes(), {})
    assert summary.graph is not None
    assert summary.graph.kept_clips == 2 and summary.graph.kept_frames == 300
    assert summary.graph.moving_frames > 200  # the walks travel
    assert [(d.clip, d.frames) for d in summary.graph.dropped] == [("arms-up", 150)]
    assert summary.graph.dropped_frames == 150 and summary.graph.leaf_edges > 0

    # segue inspect DIR: the same summary, every clip left out listed
    assert main(["inspect", str(tmp_path / "db"), "--json"]) == 0
    assert DatabaseSummary.model_validate_json(capsys.readouterr().out) == summary
    assert main(["inspect", str(tmp_path / "db")]) == 0
    out = capsys.readouterr().out
    assert "  kind       graph\n  clips      3, 450 frames at 30 fps (15.0 s)\n" in out
    assert "    arms-up (150 frames): no transition below tau" in out
    hint = kept_lines(tmp_path / "db", limit=0)[-1]  # segue build shows 20 and says where the rest are
    assert hint.startswith("  ... and 1 more (`segue inspect ") and "lists them all" in hint
    assert main(["inspect", str(tmp_path)]) == 2  # a folder, not a database
    assert "not a database segue build wrote" in capsys.readouterr().err


def build_two_walks(
    tmp_path: Path, settings: dict[str, Any], first_labels: list[dict[str, Any]] | None = None
) -> DatabaseSummary:
    """`segue build` of a graph spec of two synthetic walks (``walk-a`` labelled ``first_labels``,
    ``walk-b`` heading 90 degrees) with ``settings``, into ``tmp_path/db``; its summary."""
    clips = {"walk-a": walking_biped(150, seed=0), "walk-b": walking_biped(150, seed=1, heading_deg=90.0)}
    for name, m in clips.items():
        write_bvh(m, tmp_path / f"{name}.bvh")
    spec: dict[str, Any] = {"kind": "graph", **settings}
    spec["clips"] = [{"bvh": f"{name}.bvh", "units": "m"} for name in clips]
    spec["clips"][0]["labels"] = first_labels or []
    (tmp_path / "db.json").write_text(json.dumps(spec), encoding="utf-8")
    assert main(["build", str(tmp_path / "db.json"), "--out", str(tmp_path / "db"), "-q"]) == 0
    stored = json.loads((tmp_path / "db" / "spec.json").read_text(encoding="utf-8"))
    return summarize(stored, (tmp_path / "db" / "data.npz").read_bytes(), {})


def test_mirror_adds_the_mirror_image_of_every_clip(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    summary = build_two_walks(tmp_path, {"mirror": True})
    assert [c.name for c in summary.clips] == ["walk-a", "walk-b", "walk-a (mirror)", "walk-b (mirror)"]
    assert [c.frames for c in summary.clips] == [150] * 4
    with np.load(tmp_path / "db" / "data.npz") as z:
        lib = library_from_arrays(z)
    a, m = lib.motions[0].global_positions(), lib.motions[2].global_positions()
    partner, _ = mirror_map(lib.motions[0].skeleton.names)
    np.testing.assert_allclose(m[:, :, 0], -a[:, partner, 0], atol=1e-9)  # x -> -x, left <-> right
    np.testing.assert_allclose(m[:, :, 1:], a[:, partner, 1:], atol=1e-9)
    assert summary.graph is not None and summary.graph.kept_clips == 4  # the mirrors join the graph


def test_speeds_add_time_scaled_copies_of_every_clip_and_mirror_image(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    labels = [{"label": "step-left-foot", "start": 30, "end": 120}]
    summary = build_two_walks(tmp_path, {"mirror": True, "speeds": [0.9, 1.2]}, labels)
    images = ["walk-a", "walk-b", "walk-a (mirror)", "walk-b (mirror)"]
    assert [c.name for c in summary.clips] == images + [f"{n} (x{s:g})" for s in (0.9, 1.2) for n in images]
    # 150 frames at 30 fps played at 0.9 / 1.2: 166 / 125 frames at 30 fps
    assert [c.frames for c in summary.clips] == [150] * 4 + [166] * 4 + [125] * 4
    # labels on the copies' frames: [30, 120) played at 0.9 is [33, 134), at 1.2 [25, 100)
    labels = {c.name: [(lb.label, lb.start, lb.end) for lb in c.labels] for c in summary.clips}
    assert labels["walk-a (x0.9)"] == [("step-left-foot", 33, 134)]
    assert labels["walk-a (mirror) (x1.2)"] == [("step-right-foot", 25, 100)]
    assert labels["walk-b (x1.2)"] == [] and all(c.source_units == "m" for c in summary.clips)
    with np.load(tmp_path / "db" / "data.npz") as z:
        lib = library_from_arrays(z)
    image, fast = lib.clip("walk-b (mirror)").global_positions(), lib.clip("walk-b (mirror) (x1.2)")
    np.testing.assert_allclose(fast.global_positions()[::5], image[::6], atol=1e-5)  # stored as float32
    # the copies at 0.9 join the graph; the synthetic walk at 1.2 is too far from it (tau 1): left out
    assert summary.graph is not None and summary.graph.kept_clips == 8
    assert sorted(d.clip for d in summary.graph.dropped) == sorted(f"{n} (x1.2)" for n in images)
