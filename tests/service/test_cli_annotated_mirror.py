"""``segue build`` of an annotated spec with ``mirror``: the mirror images are clips of the
database, with their clips' labels, sides exchanged, in the summary."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from motion.bvh import write_bvh
from service.cli import main
from tests.engines.graph_synthetic import arc_biped
from workers.summary import database_dir_summary


def test_build_adds_mirror_images_with_mirrored_labels(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_bvh(arc_biped(90, 1.2, 40.0, seed=1), tmp_path / "a.bvh")
    write_bvh(arc_biped(90, 1.2, 0.0, seed=2), tmp_path / "b.bvh")
    spec = {
        "kind": "annotated",
        "mirror": True,
        "gammas": [1.0],
        "clips": [
            {"bvh": "a.bvh", "units": "m", "labels": [{"label": "turn-left", "start": 0, "end": 90}]},
            {"bvh": "b.bvh", "units": "m", "labels": [{"label": "walk", "start": 0, "end": 90}]},
        ],
    }
    (tmp_path / "db.json").write_text(json.dumps(spec), encoding="utf-8")
    assert main(["build", str(tmp_path / "db.json"), "--out", str(tmp_path / "db")]) == 0
    assert "4 clips, 360 frames" in capsys.readouterr().out
    summary = database_dir_summary(tmp_path / "db")
    assert [c.name for c in summary.clips] == ["a", "b", "a (mirror)", "b (mirror)"]
    assert [(lb.label, lb.end) for lb in summary.clips[2].labels] == [("turn-right", 90)]
    assert [lb.label for lb in summary.clips[3].labels] == ["walk"]
    assert summary.clips[2].source_units == "m"
    assert summary.labels == ["turn-left", "turn-right", "walk"]
