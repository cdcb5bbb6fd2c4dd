"""``segue demo ENGINE``: every engine end to end from the bundled samples, in an empty folder,
with an ``ok`` result, its BVH, GLB and report, and specs that work from anywhere."""

from __future__ import annotations

import itertools
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from motion import parse_bvh
from service.cli import main
from service.demos import DEMOS, s_curve


@pytest.fixture(scope="module")
def demo_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``segue demo all`` run once, as a separate process, in an empty folder with no ../shared
    beside it (the bundled samples live in the installed package)."""
    root = tmp_path_factory.mktemp("empty") / "user"
    root.mkdir()
    r = subprocess.run(
        [sys.executable, "-m", "service.cli", "demo", "all"],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=900,  # a hang guard: every engine's demo, maybe compiling numba's kernels, on a busy machine
        env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(Path(__file__).resolve().parents[2])},
    )
    assert r.returncode == 0, r.stderr[-3000:]
    (root / "stdout.txt").write_text(r.stdout)
    return root


@pytest.mark.parametrize("name", list(DEMOS))
def test_each_demo_writes_an_ok_result_its_files_and_how_to_repeat_it(demo_root: Path, name: str) -> None:
    demo = DEMOS[name]
    folder = demo_root / "segue-demo" / name
    out = (demo_root / "stdout.txt").read_text()
    block = out[out.index(f"segue demo {name}:") :]
    assert "quality: ok" in block.split("segue demo ", 2)[1]
    kind = demo.spec["kind"]
    assert f"built {'an' if kind == 'annotated' else 'a'} {kind} database:" in block
    report = json.loads((folder / "report.json").read_text())
    assert report["ok"] is True and report["reasons"] == [] and report["engine"] == demo.engine
    bvh = parse_bvh((folder / f"{demo.output}.bvh").read_bytes(), source=demo.output)
    assert bvh.num_frames == report["frames"] == len(report["provenance"])
    if "sample:salsa" in (folder / "db.json").read_text():
        # the salsa samples in the unit the sample catalogue declares (cmu-scaled): 1.46 m dancers
        pos = bvh.global_positions()[::5]
        height_m = float(np.median(pos[..., 1].max(axis=1) - pos[..., 1].min(axis=1))) * bvh.metres_per_unit
        assert 1.4 <= height_m <= 1.6, height_m
    assert (folder / f"{demo.output}.glb").read_bytes()[:4] == b"glTF"
    for extra in demo.extra:
        assert (folder / extra).read_bytes()[:4] == b"glTF"
    # the spec and the request name bundled samples, never a path of this machine
    for file in ("db.json", "request.json", "job.json"):
        text = (folder / file).read_text()
        assert str(demo_root) not in text and "/" not in json.dumps(json.loads(text)).replace("\\/", "")
    assert json.loads((folder / "request.json").read_text()) == demo.request
    job = json.loads((folder / "job.json").read_text())
    assert job == {**demo.request, "database": json.loads((folder / "db" / "info.json").read_text())["id"]}
    # what the demo printed: the files to open and the same job by CLI and over HTTP
    assert f"segue build segue-demo/{name}/db.json --out segue-demo/{name}/db" in block
    assert f"segue synth segue-demo/{name}/request.json --db segue-demo/{name}/db" in block
    assert f"-d @segue-demo/{name}/job.json http://127.0.0.1:8000/v1/jobs" in block


def test_printed_cli_commands_repeat_the_demo(
    demo_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The CLI lines a demo prints, run verbatim beside its spec and request, give the same result."""
    out = (demo_root / "stdout.txt").read_text()
    lines = [ln.strip() for ln in out.splitlines() if ln.strip().startswith("segue ") and "/walk/" in ln]
    assert [ln.split()[1] for ln in lines] == ["build", "synth"]
    (tmp_path / "segue-demo" / "walk").mkdir(parents=True)
    for file in ("db.json", "request.json"):
        shutil.copy(demo_root / "segue-demo" / "walk" / file, tmp_path / "segue-demo" / "walk" / file)
    monkeypatch.chdir(tmp_path)
    for line in lines:
        assert main(line.split()[1:]) == 0, line
    assert "quality: ok" in capsys.readouterr().out
    first = json.loads((demo_root / "segue-demo" / "walk" / "report.json").read_text())
    second = json.loads((tmp_path / "segue-demo" / "walk" / "report.json").read_text())
    assert second["provenance"] == first["provenance"] and second["ok"] is True


def test_plain_demo_is_the_readme_job(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``segue demo`` without an engine: the salsa leader converted, a dance to 120 BPM, and a spec
    that names the bundled clip rather than a path of this machine."""
    assert main(["demo", "--out", str(tmp_path)]) == 0
    assert {"salsa-leader.glb", "salsa-leader.json", "salsa-leader.npz"} <= {
        p.name for p in tmp_path.iterdir()
    }
    dance = parse_bvh((tmp_path / "salsa-dance.bvh").read_bytes(), source="salsa-dance.bvh")
    assert abs(dance.num_frames / dance.fps - 12.0) < 0.05  # 12 s of music
    report = json.loads((tmp_path / "salsa-dance-report.json").read_text())
    assert len(report["annotations"]["music_beats_s"]) == 25 and len(report["provenance"]) == dance.num_frames
    assert (tmp_path / "salsa-dance.glb").read_bytes()[:4] == b"glTF"
    spec = json.loads((tmp_path / "dance-db.json").read_text())
    assert spec["clips"] == [{"bvh": "sample:salsa-leader"}]
    out = capsys.readouterr().out
    assert "segue demo {control,walk,graph,annotations,rhythm}" in out
    assert "height 1.46 m (cmu-scaled)" in out


def test_unknown_demo_is_an_argument_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["demo", "dance"])
    assert exc.value.code == 2 and "invalid choice: 'dance'" in capsys.readouterr().err


def test_s_curve_is_a_performed_path() -> None:
    pts = s_curve(5.0, 1.2, 6.0)
    assert len(pts) == 181 and pts[0] == [0.0, 0.0]
    steps = [((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2) ** 0.5 for a, b in itertools.pairwise(pts)]
    assert max(abs(s - 0.04) for s in steps) < 2e-3  # 1.2 m/s at 30 fps
    assert pts[90][0] > 0.5 and abs(pts[-1][0] - 2 * pts[90][0]) < 0.1  # right, then back to straight
    with pytest.raises(ValueError, match="positive"):
        s_curve(0, 1, 1)
