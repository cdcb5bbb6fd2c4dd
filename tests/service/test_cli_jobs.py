"""`segue build` and `segue synth`: the CLI face of the job runtime."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from motion import read_bvh
from motion.samples import sample_path
from service.cli import main


@pytest.fixture
def spec_dir(tmp_path: Path) -> Path:
    shutil.copy(sample_path("walk"), tmp_path / "walk.bvh.gz")
    (tmp_path / "db.json").write_text(
        json.dumps({"kind": "clips", "clips": [{"bvh": "walk.bvh.gz"}], "fps": 60})
    )
    return tmp_path


def test_build_then_synth_every_format(spec_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(
            [
                "build",
                str(spec_dir / "db.json"),
                "--out",
                str(spec_dir / "db"),
                "--events",
                str(spec_dir / "build.jsonl"),
            ]
        )
        == 0
    )
    info = json.loads((spec_dir / "db" / "info.json").read_text())
    assert info["status"] == "ready" and info["clips"] == ["walk"] and info["fps"] == 60.0
    events = [json.loads(line) for line in (spec_dir / "build.jsonl").read_text().splitlines()]
    assert events[0]["type"] == "started" and events[-1]["type"] == "done"
    assert [e["id"] for e in events] == list(range(1, len(events) + 1))

    (spec_dir / "req.json").write_text(json.dumps({"engine": "clip", "clip": "walk", "start": 10, "end": 70}))
    for ext in ("bvh", "glb", "json", "npz"):
        out = spec_dir / f"out.{ext}"
        assert (
            main(
                [
                    "synth",
                    str(spec_dir / "req.json"),
                    "--db",
                    str(spec_dir / "db"),
                    "--out",
                    str(out),
                    "--report",
                    str(spec_dir / "report.json"),
                    "--events",
                    str(spec_dir / "ev.jsonl"),
                    "-q",
                ]
            )
            == 0
        )
        assert out.stat().st_size > 0
    report = json.loads((spec_dir / "report.json").read_text())
    assert report["frames"] == 60 and len(report["provenance"]) == 60
    assert report["provenance"][0] == {"clip": "walk", "frame": 10, "weights": None}
    out = read_bvh(spec_dir / "out.bvh", units="m")
    src = read_bvh(sample_path("walk")).to_units("m")
    np.testing.assert_allclose(
        out.global_positions()[0], src.global_positions()[20], atol=1e-5
    )  # 60 of 120 fps
    types = [json.loads(line)["type"] for line in (spec_dir / "ev.jsonl").read_text().splitlines()]
    assert types == ["started", "solution", "done"]


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"kind": "clips", "clips": [{"bvh": "missing.bvh"}]}, "missing.bvh"),
        ({"kind": "control", "clips": [{"bvh": "walk.bvh.gz"}]}, "pairs"),
        ({"kind": "clips", "clips": [{"bvh": "walk.bvh.gz"}], "fps": 0}, "fps"),
    ],
)
def test_build_errors(spec_dir: Path, spec: dict, message: str, capsys: pytest.CaptureFixture[str]) -> None:
    (spec_dir / "bad.json").write_text(json.dumps(spec))
    assert main(["build", str(spec_dir / "bad.json"), "--out", str(spec_dir / "x"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("segue: error:") and message in err


def test_synth_errors(spec_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["build", str(spec_dir / "db.json"), "--out", str(spec_dir / "db"), "-q"]) == 0
    cases = [
        ({"engine": "clip", "clip": "nope"}, "no clip named 'nope'"),
        ({"engine": "teleport"}, "unknown engine"),
        ({"engine": "clip", "clip": "walk", "start": 99999}, "outside clip"),
    ]
    for request, message in cases:
        (spec_dir / "r.json").write_text(json.dumps(request))
        code = main(
            [
                "synth",
                str(spec_dir / "r.json"),
                "--db",
                str(spec_dir / "db"),
                "--out",
                str(spec_dir / "o.bvh"),
                "-q",
            ]
        )
        assert code == 2
        assert message in capsys.readouterr().err
    (spec_dir / "r.json").write_text(json.dumps({"engine": "clip", "clip": "walk"}))
    assert (
        main(
            [
                "synth",
                str(spec_dir / "r.json"),
                "--db",
                str(spec_dir / "nodb"),
                "--out",
                str(spec_dir / "o.bvh"),
            ]
        )
        == 2
    )
    assert "not a database directory" in capsys.readouterr().err


def test_spec_files_name_samples_and_label_ranges_stay_inside_clips(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``sample:NAME`` works in spec files (from any folder); a label range past its clip's end
    stops the build with a message naming it (it was clamped silently before)."""
    spec = {"kind": "clips", "clips": [{"bvh": "sample:run-09-03"}], "fps": 30}
    (tmp_path / "db.json").write_text(json.dumps(spec))
    assert main(["build", str(tmp_path / "db.json"), "--out", str(tmp_path / "db"), "-q"]) == 0
    info = json.loads((tmp_path / "db" / "info.json").read_text())
    assert info["clips"] == ["run-09-03"] and info["frames"] == 33
    spec = {
        "kind": "annotated",
        "clips": [
            {"bvh": "sample:run-09-03", "labels": [{"label": "run", "start": 0, "end": 33}]},
            {"bvh": "sample:run-09-04", "labels": [{"label": "run", "start": 5, "end": 40}]},
        ],
    }
    (tmp_path / "bad.json").write_text(json.dumps(spec))
    assert main(["build", str(tmp_path / "bad.json"), "--out", str(tmp_path / "bad"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "clips[1] (run-09-04): labels[0] 'run' [5, 40) ends after the clip, which has 35 frames" in err
    assert "clips[0]" not in err  # [0, 33) of a 33-frame clip is fine


def test_synth_glb_and_json_carry_the_results_beats_and_labels(tmp_path: Path) -> None:
    from motion.export.glb import glb_bytes
    from schemas import Report
    from workers.local import write_result

    m = read_bvh(sample_path("walk")).slice(1, 61)
    ann = {"music_beats_s": [0.1, 0.2], "achieved_ranges": {"walk": [[0, 30]]}}
    report = Report(
        job="j", result="r1", engine="x", score=0.0, frames=60, fps=m.fps, provenance=[], annotations=ann
    )
    write_result(m, report, tmp_path / "a.glb", None)
    write_result(m, report, tmp_path / "a.json", None)
    write_result(m, report, tmp_path / "a.bvh", None)  # BVH has no place for events: written without
    raw = (tmp_path / "a.glb").read_bytes()
    n = int.from_bytes(raw[12:16], "little")
    events = json.loads(raw[20 : 20 + n])["animations"][0]["extras"]["events"]
    assert [e["type"] for e in events] == ["label", "beat", "beat"]  # by time: the label starts at 0
    assert json.loads((tmp_path / "a.json").read_text())["events"] == events
    plain = Report(job="j", result="r1", engine="x", score=0.0, frames=60, fps=m.fps, provenance=[])
    write_result(m, plain, tmp_path / "b.glb", None)
    assert (tmp_path / "b.glb").read_bytes() == glb_bytes(m)  # nothing to add: no extras


def test_synth_feet_overrides_the_request(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``segue synth --feet``: the request's ``feet`` (lock by default through ``footskate``); an
    engine without a foot clean-up refuses it."""
    from service.demos import DEMOS

    demo = DEMOS["rhythm"]
    (tmp_path / "db.json").write_text(json.dumps(demo.spec))
    (tmp_path / "req.json").write_text(json.dumps(demo.request))
    assert main(["build", str(tmp_path / "db.json"), "--out", str(tmp_path / "db"), "-q"]) == 0
    outs = {}
    for feet in (None, "lock", "grounding", "free"):
        out = tmp_path / f"{feet}.bvh"
        args = ["synth", str(tmp_path / "req.json"), "--db", str(tmp_path / "db"), "--out", str(out), "-q"]
        assert main(args + (["--feet", feet] if feet else [])) == 0
        outs[feet] = out.read_bytes()
    assert outs[None] == outs["lock"]
    assert len({outs[f] for f in ("lock", "grounding", "free")}) == 3
    request = json.loads((tmp_path / "req.json").read_text())
    (tmp_path / "req2.json").write_text(json.dumps({**request, "feet": "grounding"}))
    out2 = tmp_path / "in-request.bvh"
    assert (
        main(["synth", str(tmp_path / "req2.json"), "--db", str(tmp_path / "db"), "--out", str(out2), "-q"])
        == 0
    )
    assert out2.read_bytes() == outs["grounding"]
    spec_dir = tmp_path / "clips"
    spec_dir.mkdir()
    shutil.copy(sample_path("walk"), spec_dir / "walk.bvh.gz")
    (spec_dir / "db.json").write_text(json.dumps({"kind": "clips", "clips": [{"bvh": "walk.bvh.gz"}]}))
    (spec_dir / "r.json").write_text(json.dumps({"engine": "clip", "clip": "walk"}))
    assert main(["build", str(spec_dir / "db.json"), "--out", str(spec_dir / "db"), "-q"]) == 0
    args = ["synth", str(spec_dir / "r.json"), "--db", str(spec_dir / "db"), "--out", str(spec_dir / "o.bvh")]
    assert main([*args, "--feet", "lock"]) == 2
    assert "no foot clean-up" in capsys.readouterr().err
