"""``segue inspect`` on Segue's own exports: an Unreal BVH (Z up, centimetres) and a GLB, each at
its source's height."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.cli import main


def inspect(capsys: pytest.CaptureFixture[str], *args: str) -> dict[str, object]:
    capsys.readouterr()
    assert main(["inspect", *args, "--json"]) == 0
    return dict(json.loads(capsys.readouterr().out))


@pytest.fixture(scope="module")
def exports(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("exports")
    for target, name in (
        ("unreal", "walk_unreal.bvh"),
        ("gltf", "walk.glb"),
        ("unreal", "leader_unreal.bvh"),
    ):
        src = "sample:salsa-leader-12" if name.startswith("leader") else "sample:walk"
        assert main(["convert", src, str(out / name), "--target", target, "-q"]) == 0
    return out


def test_unreal_bvh_is_measured_along_its_z_axis(exports: Path, capsys: pytest.CaptureFixture[str]) -> None:
    source = inspect(capsys, "sample:walk")
    assert source["up"] == "y" and source["up_source"] == "detected"
    walk = inspect(capsys, str(exports / "walk_unreal.bvh"))
    assert walk["up"] == "z" and walk["units"] == "cm" and walk["units_source"] == "guess"
    assert walk["height_m"] == pytest.approx(source["height_m"], rel=0.01)  # ~1.49 m, was 2.10-2.17 m
    leader = inspect(capsys, str(exports / "leader_unreal.bvh"))  # exported in cm from cmu-scaled
    assert leader["up"] == "z" and leader["height_m"] == pytest.approx(1.46, abs=0.02)
    # declared: as told (Y up: the walker's depth, read in the unit it suggests)
    forced = inspect(capsys, str(exports / "walk_unreal.bvh"), "--up", "y")
    assert (
        forced["up"] == "y" and forced["up_source"] == "declared" and forced["height_m"] != walk["height_m"]
    )
    assert main(["inspect", str(exports / "walk_unreal.bvh")]) == 0
    assert "up axis    Z (detected)" in capsys.readouterr().out


def test_glb_is_read_with_its_animation_timing(exports: Path, capsys: pytest.CaptureFixture[str]) -> None:
    glb = inspect(capsys, str(exports / "walk.glb"))
    # sample:walk's 317 frames less the 4 of its reference-pose lead (dropped from samples on convert)
    assert glb["frames"] == 313 and glb["fps"] == 120.0 and glb["duration_s"] == pytest.approx(312 / 120)
    assert glb["units"] == "m" and glb["units_source"] == "gltf" and glb["up"] == "y"
    # the animation's own joints: Segue's ground root (for game engines) is folded back into the hips
    assert glb["joints"][:2] == ["hip", "abdomen"] and len(glb["joints"]) == 43  # type: ignore[index,arg-type]
    assert glb["animations"] == [
        {
            "index": 0,
            "name": "07_01_walk_daz",
            "frames": 313,
            "fps": 120.0,
            "duration_s": pytest.approx(312 / 120),
        }
    ]
    # one height (issue 39): the motion's standing height, the BVH's and its GLB's alike (it read
    # the GLB's bind pose, 5 cm taller, before)
    bvh_out = exports / "walk_again.bvh"
    assert main(["convert", "sample:walk", str(bvh_out), "-q"]) == 0
    assert glb["height_m"] == pytest.approx(inspect(capsys, str(bvh_out))["height_m"], abs=1e-4)
    assert main(["inspect", str(exports / "walk.glb")]) == 0
    assert "glTF files are in metres" in capsys.readouterr().out
    assert main(["inspect", str(exports / "walk.glb"), "--units", "cm"]) == 2
    assert "a glTF file is in metres" in capsys.readouterr().err


CORPUS = Path(__file__).resolve().parents[1] / "data" / "bvh-corpus"


def test_inspect_and_convert_print_what_a_file_needed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Regression (issue 39): a real BVH with Frames: 3069 and 3070 frame lines was refused everywhere.
    boxing = str(CORPUS / "Boxing_Toes.bvh.gz")
    said = "segue: warning: " + boxing + ":128: Frames: 3069, but the file holds 3070 frame lines: read 3070"
    info = inspect(capsys, boxing)
    assert info["frames"] == 3070 and info["warnings"] == [
        "line 128: Frames: 3069, but the file holds 3070 frame lines: read 3070 (the lines present win)"
    ]
    assert main(["inspect", boxing]) == 0
    out, err = capsys.readouterr()
    assert said in err and "frames     3070 at 100 fps" in out
    assert "height     1.62 m (162.1 cm), standing" in out  # metres first, the file's unit beside
    assert main(["convert", boxing, str(tmp_path / "boxing.glb"), "-q"]) == 0
    assert said in capsys.readouterr().err


def test_a_metre_file_says_its_height_once(exports: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # Regression (issue 39): "height 1.52 file units = 1.52 m in m"
    assert main(["inspect", str(exports / "walk.glb")]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.strip().startswith("height"))
    assert line.split() == ["height", line.split()[1], "m,", "standing"]


def test_inspect_lists_every_animation_and_reads_the_one_asked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Regression (issue 39): segue inspect of a GLB reported only its first animation
    from motion.export.characters import combine_characters
    from motion.export.glb import write_glb
    from motion.io import load_motion

    walk = load_motion("sample:walk-05-01").to_units("m").slice(0, 30)
    run = load_motion("sample:run-09-01").to_units("m").slice(0, 30)
    crowd = tmp_path / "crowd.glb"
    write_glb(combine_characters([walk, run], ["c0_", "c1_"]), crowd)
    info = inspect(capsys, str(crowd))
    names = [a["name"] for a in info["animations"]]  # type: ignore[union-attr]
    assert len(names) == 2 and info["animation"] == names[0]
    second = inspect(capsys, str(crowd), "--animation", "1")
    assert second["animation"] == names[1] and second["joints"][0] == "c1_" + run.skeleton.names[0]  # type: ignore[index]
    assert main(["inspect", str(crowd)]) == 0
    out = capsys.readouterr().out
    assert f"* 0 {names[0]!r}: 30 frames at 30 fps" in out and f"  1 {names[1]!r}: 30 frames" in out
    back = tmp_path / "run.bvh"
    assert main(["convert", str(crowd), str(back), "--animation", names[1], "-q"]) == 0
    got = load_motion(back).to_units("m")
    assert got.num_frames == 30
    import numpy as np

    assert float(np.abs(got.global_positions() - run.global_positions()).max()) < 1e-4
    assert main(["inspect", str(crowd), "--animation", "dance"]) == 2
    assert "no animation named 'dance'" in capsys.readouterr().err
