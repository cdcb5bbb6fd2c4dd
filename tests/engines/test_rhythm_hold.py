"""Rhythm couples' hand hold (request ``hand_hold``): measured on the output by the quality report,
beside what the example couples do; end to end on the bundled CMU salsa couples through the CLI,
checked against an independent FK of the written BVH."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from motion.io import load_motion
from motion.samples import sample_path
from schemas.rhythm import RhythmRequest
from service.cli import main
from tests.engines.rhythm_salsa import COUPLES_SPEC
from tests.motion.bvh_helpers import read_raw_bvh, reference_fk


@pytest.fixture(scope="module")
def salsa_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A rhythm database of two bundled salsa couples (leader and follower captured together)."""
    d = tmp_path_factory.mktemp("salsa")
    spec = COUPLES_SPEC
    (d / "db.json").write_text(json.dumps(spec))
    assert main(["build", str(d / "db.json"), "--out", str(d / "db"), "-q"]) == 0
    return d / "db"


def dance(db: Path, tmp: Path, hold: dict[str, Any], characters: int = 1) -> tuple[dict[str, Any], Any, Any]:
    body = {
        "engine": "rhythm",
        "music": {"bpm": 110, "duration_s": 12},
        "couples": True,
        "characters": characters,
        "seed": 1,
        "hand_hold": hold,
    }
    (tmp / "req.json").write_text(json.dumps(body))
    out, rep = tmp / "out.bvh", tmp / "report.json"
    assert (
        main(["synth", str(tmp / "req.json"), "--db", str(db), "--out", str(out), "--report", str(rep), "-q"])
        == 0
    )
    raw = read_raw_bvh(out.read_bytes())
    return json.loads(rep.read_text()), raw, reference_fk(raw).positions


def test_hand_hold_is_measured_on_the_output(salsa_db: Path, tmp_path: Path) -> None:
    hold = {"leader_joint": "rHand", "follower_joint": "rHand", "max_cm": 30, "min_fraction": 0.3}
    report, raw, pos = dance(salsa_db, tmp_path, hold, characters=2)
    scale = 0.01 if np.median(pos[:, raw.names.index("c0_lead_head"), 1]) > 10 else 1.0
    for c in (0, 1):
        e = report["constraint_errors"][f"hold[{c}]"]
        a = pos[:, raw.names.index(f"c{c}_lead_rHand")] * scale
        b = pos[:, raw.names.index(f"c{c}_follow_rHand")] * scale
        d = np.linalg.norm(a - b, axis=1)
        assert e["held_fraction"] == pytest.approx(float(np.mean(d <= 0.30)), abs=2e-3)
        assert e["median_cm"] == pytest.approx(100 * float(np.median(d)), abs=0.05)
        assert e["max_cm"] == pytest.approx(100 * float(d.max()), abs=0.05)
        assert e["satisfied"] == (e["held_fraction"] >= 0.3)
        assert e["tolerance_cm"] == 30 and e["tolerance"] == 0.3
    # what the example couples do, for scale: the same joints in the source clips
    lead, follow = load_motion(sample_path("salsa-leader-02")), load_motion(sample_path("salsa-follower-02"))
    assert 0.0 < report["constraint_errors"]["hold[0]"]["examples_held_fraction"] < 1.0
    n = min(lead.num_frames, follow.num_frames)
    gap = np.linalg.norm(
        (lead.global_positions()[:n, lead.skeleton.index("rHand")] * lead.metres_per_unit)
        - (follow.global_positions()[:n, follow.skeleton.index("rHand")] * follow.metres_per_unit),
        axis=1,
    )
    assert float(np.median(gap)) < 2.0  # the examples are a couple: hands within reach


def test_a_hold_the_dance_does_not_keep_is_not_ok(salsa_db: Path, tmp_path: Path) -> None:
    """Hands within 2 cm for the whole dance: no salsa couple does that; the report says so."""
    report, _, _ = dance(salsa_db, tmp_path, {"max_cm": 2, "min_fraction": 1.0})
    e = report["constraint_errors"]["hold[0]"]
    assert report["ok"] is False and not e["satisfied"] and e["held_fraction"] < 1.0
    assert any(
        r.startswith("hold[0]: c0_lead.lHand and c0_follow.rHand are within 2 cm") for r in report["reasons"]
    )


def test_hand_hold_of_an_unknown_joint_fails_clearly(
    salsa_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    body = {
        "engine": "rhythm",
        "music": {"bpm": 110, "duration_s": 4},
        "couples": True,
        "hand_hold": {"leader_joint": "rPaw"},
    }
    (tmp_path / "req.json").write_text(json.dumps(body))
    code = main(
        ["synth", str(tmp_path / "req.json"), "--db", str(salsa_db), "--out", str(tmp_path / "o.bvh"), "-q"]
    )
    assert code == 2
    assert "the leader has no joint named 'rPaw'" in capsys.readouterr().err


def test_hand_hold_needs_couples() -> None:
    with pytest.raises(ValidationError, match="set 'couples'"):
        RhythmRequest.model_validate({"music": {"bpm": 100, "duration_s": 4}, "hand_hold": {}})


def test_reach_tightens_the_hold_where_the_hands_are_near(salsa_db: Path, tmp_path: Path) -> None:
    """``reach``: hands near each other are brought within the hold distance by arm IK; hands
    apart (a let-go) are left, so the largest distance does not change. Measured on the output."""
    loose, raw0, pos0 = dance(salsa_db, tmp_path, {"max_cm": 25})
    (tmp_path / "tight").mkdir()
    tight, raw1, pos1 = dance(salsa_db, tmp_path / "tight", {"max_cm": 25, "reach": True})
    a, b = loose["constraint_errors"]["hold[0]"], tight["constraint_errors"]["hold[0]"]
    assert b["held_fraction"] > a["held_fraction"] + 0.2
    assert b["max_cm"] == pytest.approx(a["max_cm"], abs=1.0)
    d = np.linalg.norm(
        pos1[:, raw1.names.index("c0_lead_lHand")] - pos1[:, raw1.names.index("c0_follow_rHand")], axis=1
    )
    scale = 0.01 if np.median(pos1[:, raw1.names.index("c0_lead_head"), 1]) > 10 else 1.0
    assert b["held_fraction"] == pytest.approx(float(np.mean(d * scale <= 0.25)), abs=2e-3)
    # only the arms move: the hips are where they were
    hip = raw0.names.index("c0_follow_hip")
    np.testing.assert_allclose(pos1[:, hip], pos0[:, hip], atol=1e-3)
