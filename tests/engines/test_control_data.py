"""The control engine on real motion capture: the bundled CMU salsa couple, and shared data when present."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from engines.base import EngineError
from engines.control.engine import ControlEngine
from engines.library import ClipInput, build_library, library_to_arrays
from motion import Motion
from motion import rotations as rot
from motion.bvh import bvh_text, parse_bvh
from motion.samples import sample_path
from schemas.databases import parse_database_spec
from schemas.jobs import parse_job_request
from tests.engines.emitters import Collect

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
POINTS = ["hip", "head", "rHand", "lHand", "rFoot", "lFoot"]


def moved(motion: Motion, yaw_deg: float, tx: float, tz: float) -> Motion:
    """The motion rotated about +Y by ``yaw_deg`` about the origin, then moved on the floor."""
    turn = rot.from_yaw(np.float64(np.radians(yaw_deg)))
    root = rot.rotate(turn, motion.root_positions) + np.array([tx, 0.0, tz])
    q = motion.rotations.copy()
    q[:, 0] = rot.multiply(turn, q[:, 0])
    return replace(motion, root_positions=root, rotations=q)


def engine_of(pairs: list[tuple[bytes, bytes]], segmentation: dict[str, object]) -> ControlEngine:
    clips, spec_pairs = [], []
    for i, (lead, follow) in enumerate(pairs):
        clips += [ClipInput(f"follow{i}", follow), ClipInput(f"lead{i}", lead)]
        spec_pairs.append(
            {
                "control": {"bvh": f"lead{i}.bvh", "name": f"lead{i}"},
                "target": {"bvh": f"follow{i}.bvh", "name": f"follow{i}"},
            }
        )
    spec = parse_database_spec({"kind": "control", "pairs": spec_pairs, "segmentation": segmentation})
    assert [c.display_name() for c in spec.clips] == [c.name for c in clips]
    library = build_library(clips, spec.fps)
    arrays = ControlEngine.build(spec, library, Collect(), lambda: False)
    arrays.update(library_to_arrays(library))
    return ControlEngine(library, arrays)


def follower_error(out: Motion, truth: Motion) -> float:
    """Mean distance of hip, head, hands and feet, metres."""
    idx = [truth.skeleton.names.index(n) for n in POINTS]
    a, b = out.global_positions()[:, idx], truth.global_positions()[:, idx]
    return float(np.linalg.norm(a - b, axis=-1).mean())


@pytest.fixture(scope="module")
def sample_couple() -> tuple[bytes, bytes]:
    return sample_path("salsa-leader").read_bytes(), sample_path("salsa-follower").read_bytes()


def test_the_follower_of_a_known_dance_is_recovered_where_it_stood(sample_couple) -> None:  # type: ignore[no-untyped-def]
    lead_b, follow_b = sample_couple
    engine = engine_of([sample_couple], {"method": "fixed", "seconds": 0.6})
    lead = parse_bvh(lead_b).with_units("m").slice(0, 600)  # 5 s at 120 fps
    follow = parse_bvh(follow_b).with_units("m").slice(0, 600)
    lead, follow = moved(lead, 35.0, 1.5, -0.7), moved(follow, 35.0, 1.5, -0.7)
    req = parse_job_request({"engine": "control", "control": {"bvh": "lead.bvh"}, "budget_s": 5})
    req.attach_inputs({"lead.bvh": bvh_text(lead).encode()})
    out = Collect()
    engine.search(req, 5.0, out, lambda: False)
    sol = out.solutions[-1]
    assert sol.motion.num_frames == 600 and sol.motion.fps == 120.0  # the control's length and rate
    assert follower_error(sol.motion, follow) < 0.08  # the same dance: where the real follower stood
    assert {c for c, _ in sol.provenance} == {"follow0"} and len(sol.provenance) == 600
    segs = sol.annotations["segments"]
    assert segs[0]["heading_deg"] == pytest.approx(35.0, abs=2.0)
    assert sum(s["duration_s"] for s in segs) == pytest.approx(5.0, abs=0.05)
    assert len(sol.annotations["handhold"]) == 600 and set(sol.annotations["handhold"]) <= {0, 1}
    assert sol.terms["interpretation"] >= 0 and sol.score == pytest.approx(sum(sol.terms.values()))
    # hard constraint: at 2 s, the instance holding the follower's frame 450 (database rate 30 fps)
    req = parse_job_request(
        {
            "engine": "control",
            "control": {"bvh": "lead.bvh"},
            "constraints": [{"time_s": 2.0, "clip": "follow0", "clip_frame": 450}],
        }
    )
    req.attach_inputs({"lead.bvh": bvh_text(lead).encode()})
    out = Collect()
    engine.search(req, 5.0, out, lambda: False)
    seg = [
        s
        for s in out.solutions[-1].annotations["segments"]
        if s["start_s"] <= 2.0 < s["start_s"] + s["duration_s"]
    ]
    assert len(seg) == 1 and seg[0]["source_start"] <= 450 < seg[0]["source_start"] + seg[0]["source_frames"]
    # a control file the runtime did not attach is refused with a clear error
    req = parse_job_request({"engine": "control", "control": {"bvh": "x.bvh"}})
    with pytest.raises(EngineError, match="not provided"):
        engine.search(req, 5.0, Collect(), lambda: False)


@pytest.mark.skipif(not (DATA / "cmu-salsa").exists(), reason="shared data absent")
def test_leave_one_out_salsa_beats_the_average_partner() -> None:
    s = DATA / "cmu-salsa"
    pairs = [
        ((s / f"60_{t}_scaled.bvh").read_bytes(), (s / f"61_{t}_scaled.bvh").read_bytes())
        for t in ("01", "02", "04", "05")
    ]
    engine = engine_of(pairs, {"method": "beats", "beats_per_segment": 2})
    assert engine.db.instances.shape[0] > 50
    lead = parse_bvh((s / "60_03_scaled.bvh").read_bytes()).with_units("m").slice(0, 960)
    follow = parse_bvh((s / "61_03_scaled.bvh").read_bytes()).with_units("m").slice(0, 960)
    req = parse_job_request({"engine": "control", "control": {"bvh": "lead.bvh"}, "exact": False})
    req.attach_inputs({"lead.bvh": bvh_text(lead).encode()})
    out = Collect()
    engine.search(req, 10.0, out, lambda: False)
    height = float(lead.global_positions()[:, lead.skeleton.names.index("head"), 1].max())
    assert follower_error(out.solutions[-1].motion, follow) / height < 0.3  # average partner: 0.375


def test_pairs_build_and_synth_through_the_cli_runtime(tmp_path: Path, sample_couple) -> None:  # type: ignore[no-untyped-def]
    """``segue build`` / ``segue synth`` code paths: pairs resolved relative to the spec file, the
    control BVH relative to the request file."""
    import json

    from workers.local import build_to_dir, synth_from_dir

    lead_b, follow_b = sample_couple
    (tmp_path / "clips").mkdir()
    (tmp_path / "clips" / "60_01.bvh").write_bytes(lead_b)
    (tmp_path / "clips" / "61_01.bvh").write_bytes(follow_b)
    spec = {
        "kind": "control",
        "pairs": [{"control": "clips/60_01.bvh", "target": "clips/61_01.bvh"}],
        "segmentation": {"method": "fixed", "seconds": 0.6},
    }
    (tmp_path / "db.json").write_text(json.dumps(spec))
    events: list[str] = []
    info = build_to_dir(tmp_path / "db.json", tmp_path / "db", lambda t, d: events.append(str(t)))
    assert info.kind == "control" and info.clips == ["61_01", "60_01"]
    lead = parse_bvh(lead_b).slice(0, 360)
    (tmp_path / "req").mkdir()
    (tmp_path / "req" / "lead.bvh").write_text(bvh_text(lead))
    (tmp_path / "req" / "r.json").write_text(
        json.dumps({"engine": "control", "control": {"bvh": "lead.bvh"}})
    )
    result = synth_from_dir(
        tmp_path / "req" / "r.json", tmp_path / "db", lambda t, d: events.append(str(t)), 5.0
    )
    assert result is not None
    motion, report = result
    assert motion.num_frames == 360 and report.fps == 120.0 and len(report.provenance) == 360
    assert report.annotations["segments"] and "foot_slide_m_s" in report.metrics and report.ok is not None


def test_the_report_says_whether_the_feet_stay_where_the_examples_plant_them(sample_couple) -> None:  # type: ignore[no-untyped-def]
    """The foot contacts carried over from the examples are a goal of the report, measured on the
    output: met with the foot clean-up (the default), not met without it (the pieces slide more
    than the examples' own feet do)."""
    pairs = [sample_couple] + [
        (sample_path(f"salsa-leader-{t}").read_bytes(), sample_path(f"salsa-follower-{t}").read_bytes())
        for t in ("02", "04")
    ]
    engine = engine_of(pairs, {"method": "beats", "beats_per_segment": 2})
    lead = parse_bvh(sample_path("salsa-leader-12").read_bytes()).with_units("m").slice(0, 960)  # 8 s
    examples = engine.examples_planted_slide()
    assert examples is not None and 0.02 < examples < 0.5  # salsa feet swivel while planted
    entries = {}
    for cleanup in (True, False):
        req = parse_job_request({"engine": "control", "control": {"bvh": "lead.bvh"}, "footskate": cleanup})
        req.attach_inputs({"lead.bvh": bvh_text(lead).encode()})
        out = Collect()
        engine.search(req, 5.0, out, lambda: False)
        sol = out.solutions[-1]
        assert sol.quality is not None
        entries[cleanup] = (sol.quality.constraint_errors["footplants"], sol.quality.reasons)
        flags = np.asarray(sol.annotations["foot_contacts"]["flags"], dtype=bool)
        assert entries[cleanup][0]["frames"] > 0.2 * flags.sum()  # most planted frames are measured
    (kept, _), (slid, reasons) = entries[True], entries[False]
    assert kept["satisfied"] and kept["slide_m_s"] < 0.5 * examples
    assert kept["tolerance_m_s"] == pytest.approx(examples, abs=1e-4)
    assert not slid["satisfied"] and slid["slide_m_s"] > examples
    assert any(r.startswith("footplants:") for r in reasons)
