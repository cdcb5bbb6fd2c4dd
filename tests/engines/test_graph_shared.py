"""Several characters with shared constraints in the graph engine (engines.graph.coupled), end to end
on real motion capture (the bundled CMU walks) through the CLI, the report checked against an
independent forward kinematics of the written BVH."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from schemas.graph import GraphRequest
from service.cli import main
from tests.motion.bvh_helpers import read_raw_bvh, reference_fk

CLIPS = ("walk-05-01", "walk-10-04", "walk-12-02", "walk")


@pytest.fixture(scope="module")
def walks_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A graph database of the bundled CMU walks (30 fps, 43-joint skeleton)."""
    d = tmp_path_factory.mktemp("walks")
    spec = {"kind": "graph", "clips": [{"bvh": f"sample:{c}", "name": c} for c in CLIPS]}
    (d / "db.json").write_text(json.dumps(spec))
    assert main(["build", str(d / "db.json"), "--out", str(d / "db"), "-q"]) == 0
    return d / "db"


def walkers(gap_z: float = 0.8, far: float = 6.0) -> list[dict[str, Any]]:
    """Two walkers heading for each other, ``far`` metres apart along X, ``gap_z`` to the side."""
    return [
        {"constraints": [{"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 90.0}]},
        {"constraints": [{"type": "body", "frame": 0, "position": [far, gap_z], "heading_deg": -90.0}]},
    ]


def synth(db: Path, tmp: Path, body: dict[str, Any]) -> tuple[dict[str, Any], Any]:
    """Run ``segue synth``; the report and the independent FK (metres) of the output BVH."""
    (tmp / "req.json").write_text(json.dumps(body))
    out, rep = tmp / "out.bvh", tmp / "report.json"
    assert (
        main(["synth", str(tmp / "req.json"), "--db", str(db), "--out", str(out), "--report", str(rep), "-q"])
        == 0
    )
    raw = read_raw_bvh(out.read_bytes())
    return json.loads(rep.read_text()), (raw, reference_fk(raw).positions)


def track(raw: Any, pos: Any, character: int, joint: str | None) -> Any:
    """``(F, 3)`` a point of the output by the reference FK: a joint, or the hips on the floor."""
    if joint is not None:
        return pos[:, raw.names.index(f"c{character}_{joint}")]
    hips = pos[:, raw.names.index(f"c{character}_hip")]
    return np.stack((hips[:, 0], np.zeros(len(hips)), hips[:, 2]), axis=-1)


def request(shared: list[dict[str, Any]], seed: int = 1, **extra: Any) -> dict[str, Any]:
    # a search bounded by rounds (not time) gives the same motion on any machine
    return {
        "engine": "graph",
        "frames": 150,
        "seed": seed,
        "rounds": 15,
        "coupling_rounds": 2,
        "budget_s": 120,
        "characters": walkers(),
        "shared": shared,
        **extra,
    }


def test_two_walkers_meet_hand_to_hand_and_keep_apart(walks_db: Path, tmp_path: Path) -> None:
    """Right hands meet at frame 75 (a high five while passing); bodies at least 0.5 m apart
    before frame 65 and from frame 85. The report's figures are those of an independent FK of the
    written BVH; the meet holds within the default 5 cm and the whole result is ok (plausible)."""
    shared = [
        {
            "type": "meet",
            "frame": 75,
            "a": {"character": 0, "joint": "rHand"},
            "b": {"character": 1, "joint": "rHand"},
        },
        {"type": "apart", "a": {"character": 0}, "b": {"character": 1}, "min_m": 0.5, "end": 65},
        {"type": "apart", "a": {"character": 0}, "b": {"character": 1}, "min_m": 0.5, "start": 85},
    ]
    report, (raw, pos) = synth(walks_db, tmp_path, request(shared))
    assert raw.names[0] == "world" and "c0_rHand" in raw.names and "c1_rHand" in raw.names
    assert pos.shape[0] == 150
    pos = pos * 0.01 if np.median(pos[:, raw.names.index("c0_head"), 1]) > 10 else pos  # cm or m
    errors = report["constraint_errors"]
    # the meet, measured independently
    d = float(np.linalg.norm(track(raw, pos, 0, "rHand")[75] - track(raw, pos, 1, "rHand")[75]))
    assert errors["shared[0]"]["distance_cm"] == pytest.approx(100 * d, abs=0.05)
    assert errors["shared[0]"]["satisfied"] and 100 * d <= 5.0
    # the separations, measured independently
    gap = np.linalg.norm((track(raw, pos, 0, None) - track(raw, pos, 1, None))[:, [0, 2]], axis=1)
    for name, lo, hi in (("shared[1]", 0, 65), ("shared[2]", 85, 150)):
        k = lo + int(np.argmin(gap[lo:hi]))
        assert errors[name]["min_distance_cm"] == pytest.approx(100 * gap[k], abs=0.05)
        assert errors[name]["frame"] == k
        assert errors[name]["satisfied"] == bool(gap[lo:hi].min() >= 0.5)
        assert errors[name]["satisfied"]
    # each character's own start is met, named per character
    assert errors["c0.body[0]"]["satisfied"] and errors["c1.body[0]"]["satisfied"]
    assert report["metrics"]["characters"] == 2
    assert report["metrics"]["shared_meet_error_cm_max"] == errors["shared[0]"]["error_cm"]
    assert report["metrics"]["shared_min_distance_cm"] == min(
        errors[n]["min_distance_cm"] for n in ("shared[1]", "shared[2]")
    )
    assert report["ok"], report["reasons"]


def test_walkers_pass_each_other_at_a_time(walks_db: Path, tmp_path: Path) -> None:
    """Passing: bodies 0.9 m apart at frame 75 (side by side), never closer than 0.5 m."""
    shared = [
        {"type": "meet", "frame": 75, "a": {"character": 0}, "b": {"character": 1}, "distance_m": 0.9},
        {"type": "apart", "a": {"character": 0}, "b": {"character": 1}, "min_m": 0.5},
    ]
    report, (raw, pos) = synth(walks_db, tmp_path, request(shared, seed=2))
    pos = pos * 0.01 if np.median(pos[:, raw.names.index("c0_head"), 1]) > 10 else pos
    gap = np.linalg.norm((track(raw, pos, 0, None) - track(raw, pos, 1, None))[:, [0, 2]], axis=1)
    errors = report["constraint_errors"]
    assert errors["shared[0]"]["distance_cm"] == pytest.approx(100 * gap[75], abs=0.05)
    assert abs(gap[75] - 0.9) <= 0.05 and errors["shared[0]"]["satisfied"]
    assert errors["shared[1]"]["min_distance_cm"] == pytest.approx(100 * gap.min(), abs=0.05)
    assert gap.min() >= 0.5 and errors["shared[1]"]["satisfied"]
    # they did pass: each ends on the other's side of where they met
    x0, x1 = track(raw, pos, 0, None)[:, 0], track(raw, pos, 1, None)[:, 0]
    assert x0[0] < x1[0] and x0[-1] > x1[-1]


def test_unreachable_shared_constraints_are_reported_not_ok(walks_db: Path, tmp_path: Path) -> None:
    """Walkers 20 m apart cannot hold hands after 10 frames, nor stay 30 m apart: the report says
    both, with the figures."""
    shared = [
        {
            "type": "meet",
            "frame": 10,
            "a": {"character": 0, "joint": "lHand"},
            "b": {"character": 1, "joint": "rHand"},
        },
        {"type": "apart", "a": {"character": 0}, "b": {"character": 1}, "min_m": 30.0},
    ]
    body = request(shared, rounds=3, coupling_rounds=1) | {"characters": walkers(gap_z=1.0, far=20.0)}
    report, (raw, pos) = synth(walks_db, tmp_path, body)
    assert report["ok"] is False
    errors = report["constraint_errors"]
    assert not errors["shared[0]"]["satisfied"] and errors["shared[0]"]["error_cm"] > 1000
    assert not errors["shared[1]"]["satisfied"] and errors["shared[1]"]["frames"] > 0
    assert any(r.startswith("shared[0] (frame 10)") for r in report["reasons"])
    assert any(r.startswith("shared[1]:") and "under 3000 cm" in r for r in report["reasons"])


def test_shared_constraint_of_an_unknown_joint_is_refused(walks_db: Path, tmp_path: Path) -> None:
    shared = [{"type": "meet", "frame": 5, "a": {"character": 0, "joint": "rPaw"}, "b": {"character": 1}}]
    (tmp_path / "req.json").write_text(json.dumps(request(shared)))
    code = main(
        ["synth", str(tmp_path / "req.json"), "--db", str(walks_db), "--out", str(tmp_path / "o.bvh"), "-q"]
    )
    assert code == 2


@pytest.mark.parametrize(
    ("shared", "message"),
    [
        (
            {"type": "meet", "frame": 5, "a": {"character": 0}, "b": {"character": 2}},
            "b.character 2 is not one of the 2 characters",
        ),
        ({"type": "meet", "frame": 150, "a": {"character": 0}, "b": {"character": 1}}, "frame 150 is past"),
        (
            {"type": "apart", "a": {"character": 0}, "b": {"character": 1}, "min_m": 0.5, "end": 151},
            "past the motion's 150 frames",
        ),
        ({"type": "meet", "frame": 5, "a": {"character": 1}, "b": {"character": 1}}, "the same character"),
    ],
)
def test_bad_shared_constraints_are_schema_errors(shared: dict[str, Any], message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        GraphRequest.model_validate(request([shared]))


def test_shared_constraints_need_characters() -> None:
    with pytest.raises(ValidationError, match="need 'characters'"):
        GraphRequest.model_validate(
            {
                "frames": 50,
                "shared": [{"type": "meet", "frame": 5, "a": {"character": 0}, "b": {"character": 1}}],
            }
        )
    with pytest.raises(ValidationError, match="top-level 'constraints' must be empty"):
        GraphRequest.model_validate(
            request([]) | {"constraints": [{"type": "body", "frame": 0, "position": [0, 0]}]}
        )


def test_shared_cost_is_finite_past_a_short_output() -> None:
    """A character whose search ran out of time with a short path shortens the output; a meet
    past its end costs like a 1 m miss, an apart counts only the frames there are."""
    from engines.graph.coupled import shared_cost
    from motion.goals import ApartGoal, MeetGoal, Point
    from tests.motion.test_goals_shared import two_points

    pos, chars = two_points()
    late = shared_cost(MeetGoal("m", 20, Point(0, 1), Point(1, 2)), 1.0, pos, chars)
    near = shared_cost(MeetGoal("m", 5, Point(0, 1), Point(1, 2), distance_m=1.7), 1.0, pos, chars)
    assert late == pytest.approx((1 / 0.3) ** 2 + (0.95 / 0.05) ** 2) and late > near > 0
    assert (
        shared_cost(ApartGoal("a", Point(0, 1), Point(1, 2), min_m=0.1, start=0, end=50), 1.0, pos, chars)
        == 0
    )
