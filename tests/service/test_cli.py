"""The ``segue`` command line, run in-process and as the installed console script."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from motion import read_bvh
from motion.samples import SAMPLES, sample_path
from service.cli import main


def test_inspect_json_on_sample(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", "sample:salsa-leader", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frames"] == 2242 and len(info["joints"]) == 43 and info["fps"] == 120.0
    assert info["units_guess"]["plausible"]
    # the sample catalogue declares the salsa samples' unit (cmu-scaled, 1.28 m): 1.46 m, not 1.15 m
    assert info["units"] == "cmu-scaled" and info["units_source"] == "sample"
    assert 1.4 < info["height_m"] < 1.5


def test_inspect_text_and_declared_units(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", "sample:walk", "--units", "cm"]) == 0
    out = capsys.readouterr().out
    assert "317 at 120 fps" in out and "cm (declared)" in out


def test_convert_all_formats(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = sample_path("walk")
    for ext in ("bvh", "bvh.gz", "glb", "json", "npz"):
        assert main(["convert", str(src), str(tmp_path / f"w.{ext}"), "--frames", "1:61", "-q"]) == 0
    z = np.load(tmp_path / "w.npz", allow_pickle=False)
    ref = read_bvh(src).slice(1, 61).global_positions()
    np.testing.assert_allclose(z["positions"], ref, atol=1e-9)  # NPZ: the file's own numbers (cm)
    again = read_bvh(tmp_path / "w.bvh")
    assert again.units == "m"
    np.testing.assert_allclose(again.global_positions(), ref / 100, atol=1e-5)  # 6 decimals of a metre
    assert (
        main(["convert", str(src), str(tmp_path / "c.bvh"), "--units", "cm", "--keep-reference", "-q"]) == 0
    )
    np.testing.assert_allclose(read_bvh(tmp_path / "c.bvh").slice(1, 61).global_positions(), ref, atol=1e-4)


def test_a_file_keeps_its_reference_frames_unless_asked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A user's file keeps its frame count (a note names the reference-pose lead); --drop-reference
    drops it; a bundled sample is cleaned by default."""
    src = sample_path("walk")
    frames = read_bvh(src).num_frames
    assert main(["convert", str(src), str(tmp_path / "kept.bvh"), "-q"]) == 0
    assert read_bvh(tmp_path / "kept.bvh").num_frames == frames
    assert "the first 4 frames look like a reference pose" in capsys.readouterr().err
    assert main(["convert", str(src), str(tmp_path / "dropped.bvh"), "--drop-reference", "-q"]) == 0
    assert read_bvh(tmp_path / "dropped.bvh").num_frames == frames - 4
    assert "dropped the first 4 frames" in capsys.readouterr().err
    assert main(["convert", "sample:walk", str(tmp_path / "sample.bvh"), "-q"]) == 0
    assert read_bvh(tmp_path / "sample.bvh").num_frames == frames - 4
    assert main(["convert", "sample:walk", str(tmp_path / "raw.bvh"), "--keep-reference", "-q"]) == 0
    assert read_bvh(tmp_path / "raw.bvh").num_frames == frames


def test_convert_fps_units_and_target(tmp_path: Path) -> None:
    out = tmp_path / "w.npz"
    assert main(["convert", "sample:walk", str(out), "--fps", "30", "--units", "m", "-q"]) == 0
    z = np.load(out, allow_pickle=False)
    # 317 frames at 120 fps less the 4 of its reference-pose lead: 313 -> 79 at 30 fps
    assert float(z["fps"]) == 30.0 and z["positions"].shape[0] == 79 and str(z["units"]) == "m"
    assert main(["convert", "sample:walk", str(tmp_path / "u.json"), "--target", "unreal", "-q"]) == 0
    doc = json.loads((tmp_path / "u.json").read_text())
    assert doc["convention"]["up"] == "+Z"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["inspect", "/no/such/file.bvh"], "cannot read file"),
        (["inspect", "sample:nope"], "no bundled sample"),
        (["convert", "sample:walk", "out.fbx"], "unsupported file type"),
        (["convert", "sample:walk", "out.npz", "--frames", "a:b"], "--frames"),
        (["convert", "sample:walk", "out.npz", "--fps", "-5"], "fps"),
    ],
)
def test_bad_input_exits_2_with_message(
    argv: list[str],
    message: str,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("segue: error:") and message in err


def test_malformed_bvh_names_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.bvh"
    bad.write_text(
        "HIERARCHY\nROOT a\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xrotation Yrotation Zrotation\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.1\n1 2 3\n1 x 3\n"
    )
    assert main(["inspect", str(bad)]) == 2
    assert "bad.bvh:11" in capsys.readouterr().err


def test_samples_and_demo(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """(The whole ``segue demo`` is tests/service/test_demos.py's.)"""
    assert main(["samples"]) == 0
    listed = capsys.readouterr().out
    assert all(f"sample:{name}" in listed for name in SAMPLES)
    quick = tmp_path / "quick"
    assert main(["demo", "--out", str(quick), "--no-synth"]) == 0
    assert {"salsa-leader.glb", "salsa-leader.json", "salsa-leader.npz"} <= {p.name for p in quick.iterdir()}
    assert not (quick / "salsa-dance.bvh").exists()


@pytest.mark.skipif(shutil.which("segue") is None, reason="console script not installed")
def test_console_script_is_installed() -> None:
    r = subprocess.run(
        ["segue", "inspect", "sample:start-walk-stop", "--json"],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    assert json.loads(r.stdout)["frames"] > 0


def test_beats_of_a_recording(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tests.engines.audio_synthetic import drifting_beats, drum_track, encode

    beats = drifting_beats(120.0, 120.0, 8.0)
    (tmp_path / "song.wav").write_bytes(encode(drum_track(beats, 8.0, seed=5)))
    assert main(["beats", str(tmp_path / "song.wav"), "--json", "--tempo-bpm", "120"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert abs(info["tempo_bpm"] - 120) < 3 and len(info["beats_s"]) >= 12
    assert main(["beats", str(tmp_path / "song.wav")]) == 0
    assert "tempo      12" in capsys.readouterr().out
    (tmp_path / "bad.ogg").write_bytes(b"OggS" + bytes(60))
    assert main(["beats", str(tmp_path / "bad.ogg")]) == 2
    assert "bad.ogg: audio: cannot decode" in capsys.readouterr().err
    assert main(["beats", "sample:walk", "--tempo-bpm", "100"]) == 2
    assert "--tempo-bpm is a hint for recordings" in capsys.readouterr().err
