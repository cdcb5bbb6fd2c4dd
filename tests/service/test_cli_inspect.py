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
