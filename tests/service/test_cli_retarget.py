"""``segue retarget``: BVH and GLB characters, outputs, the joint map and clear errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from motion import read_bvh, write_bvh
from motion.io import load_motion
from service.cli import main
from tests.motion.retarget.characters import character


@pytest.fixture
def unreal_bvh(tmp_path: Path) -> Path:
    path = tmp_path / "mannequin.bvh"
    write_bvh(character("unreal", scale=1.2), path)
    return path


def test_retarget_to_a_bvh_character(
    tmp_path: Path, unreal_bvh: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.bvh"
    assert main(["retarget", "sample:walk-05-01", "--to", str(unreal_bvh), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "CMU-Daz rig 1.42 m -> Unreal mannequin 1.84 m" in said and "units cm" in said
    got, char = read_bvh(out), read_bvh(unreal_bvh)
    src = load_motion("sample:walk-05-01")
    assert got.skeleton.names == char.skeleton.names and got.skeleton.channels == char.skeleton.channels
    np.testing.assert_allclose(got.skeleton.offsets, char.skeleton.offsets, atol=1e-6)
    assert got.num_frames == src.num_frames - 1 and got.fps == src.fps  # its reference-pose frame dropped


def test_retarget_to_glb_output_and_glb_character(tmp_path: Path, unreal_bvh: Path) -> None:
    assert (
        main(
            ["retarget", "sample:walk-05-01", "--to", str(unreal_bvh), "--out", str(tmp_path / "o.glb"), "-q"]
        )
        == 0
    )
    assert (tmp_path / "o.glb").read_bytes()[:4] == b"glTF"
    assert main(["convert", str(unreal_bvh), str(tmp_path / "char.glb"), "-q"]) == 0
    out = tmp_path / "o2.bvh"
    assert (
        main(["retarget", "sample:walk-05-01", "--to", str(tmp_path / "char.glb"), "--out", str(out), "-q"])
        == 0
    )
    assert "pelvis" in read_bvh(out).skeleton.names


def test_map_and_rest_options(tmp_path: Path, unreal_bvh: Path) -> None:
    text = unreal_bvh.read_text().replace("JOINT foot_l\n", "JOINT LAnkle\n")
    odd = tmp_path / "odd.bvh"
    odd.write_text(text)
    amap = tmp_path / "map.json"
    amap.write_text(json.dumps({"LeftFoot": "LAnkle"}))
    out = tmp_path / "o.bvh"
    args = ["retarget", "sample:walk-05-01", "--to", str(odd), "--out", str(out), "-q", "--rest", "zero"]
    assert main([*args, "--map", str(amap)]) == 0
    assert read_bvh(out).skeleton.names == read_bvh(odd).skeleton.names


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        ("missing-foot", "the character has no joint for: left foot"),
        ("bad-map-json", "invalid JSON"),
        ("map-not-object", "must be a JSON object"),
        ("map-unknown-joint", "no joint named 'Nope'"),
        ("bad-character", "no MOTION section"),
        ("missing-character", "cannot read file"),
    ],
)
def test_errors_name_the_problem(
    tmp_path: Path, unreal_bvh: Path, capsys: pytest.CaptureFixture[str], setup: str, message: str
) -> None:
    char, extra = unreal_bvh, []
    amap = tmp_path / "map.json"
    if setup == "missing-foot":
        char = tmp_path / "c.bvh"
        char.write_text(unreal_bvh.read_text().replace("JOINT foot_l\n", "JOINT LAnkle\n"))
    elif setup == "bad-map-json":
        amap.write_text("{nope")
        extra = ["--map", str(amap)]
    elif setup == "map-not-object":
        amap.write_text("[1, 2]")
        extra = ["--map", str(amap)]
    elif setup == "map-unknown-joint":
        amap.write_text('{"lFoot": "Nope"}')
        extra = ["--map", str(amap)]
    elif setup == "bad-character":
        char = tmp_path / "c.bvh"
        char.write_text("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 0\n}\n")
    elif setup == "missing-character":
        char = tmp_path / "none.bvh"
    code = main(["retarget", "sample:walk", "--to", str(char), "--out", str(tmp_path / "o.bvh"), *extra])
    assert code == 2
    assert message in capsys.readouterr().err


def test_a_bvh_character_keeps_exactly_its_hierarchy_in_glb(tmp_path: Path, unreal_bvh: Path) -> None:
    from tests.glb_writer import read_glb

    out = tmp_path / "o.glb"
    assert main(["retarget", "sample:walk-05-01", "--to", str(unreal_bvh), "--out", str(out), "-q"]) == 0
    doc, _ = read_glb(out.read_bytes())
    names = [doc["nodes"][j]["name"] for j in doc["skins"][0]["joints"]]
    assert names == list(read_bvh(unreal_bvh).skeleton.names)  # no ground joint added


def test_animation_only_needs_a_gltf_character(
    tmp_path: Path, unreal_bvh: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["retarget", "sample:walk", "--to", str(unreal_bvh), "--out", str(tmp_path / "o.glb")]
    assert main([*args, "--animation-only"]) == 2
    assert "--animation-only is for a glTF/GLB character" in capsys.readouterr().err


def test_root_motion_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tests.glb_writer import read_glb
    from tests.motion.retarget.gltf_rig import unreal_character_glb

    hero = tmp_path / "hero.glb"
    hero.write_bytes(unreal_character_glb())
    out = tmp_path / "o.glb"
    for flags, carrier in ((["--target", "unreal"], "root"), (["--target", "unity"], "pelvis")):
        assert main(["retarget", "sample:walk", "--to", str(hero), "--out", str(out), *flags]) == 0
        assert f"on {carrier!r}" in capsys.readouterr().out
        doc, _ = read_glb(out.read_bytes())
        moved = {
            doc["nodes"][c["target"]["node"]]["name"]
            for c in doc["animations"][0]["channels"]
            if c["target"]["path"] == "translation"
        }
        assert moved == ({"root", "pelvis"} if carrier == "root" else {"pelvis"})
    assert (
        main(
            [
                "retarget",
                "sample:walk",
                "--to",
                "sample:walk-10-04",
                "--out",
                str(out),
                "--root-motion",
                "root",
            ]
        )
        == 2
    )
    assert "starts at its hips" in capsys.readouterr().err


def test_feet_option_report_and_warnings(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--feet lock|grounding|free`` (lock by default, as before), the feet's figures printed and
    written (``--report``), the character's own mesh read, and a map that leaves limbs undriven
    warns naming them."""
    from tests.motion.retarget.namings import mannequin_character, role_map

    hero = tmp_path / "hero.glb"
    hero.write_bytes(mannequin_character("own"))
    amap = tmp_path / "map.json"
    amap.write_text(json.dumps(role_map("own")))
    outs = {}
    for feet in ("lock", "grounding", "free", None):
        out = tmp_path / f"out-{feet}.bvh"
        args = ["retarget", "sample:walk", "--to", str(hero), "--out", str(out), "--map", str(amap)]
        args += ["--report", str(tmp_path / f"{feet}.json")] + (["--feet", feet] if feet else [])
        assert main(args) == 0
        said = capsys.readouterr()
        assert f"feet ({feet or 'lock'}): soles at worst" in said.out and "warning" not in said.err
        outs[feet] = out.read_bytes()
    assert outs[None] == outs["lock"] and len({outs[f] for f in ("lock", "grounding", "free")}) == 3
    figures = {f: json.loads((tmp_path / f"{f}.json").read_text()) for f in ("lock", "free")}
    assert figures["lock"]["sink_cm"] <= 1.0 < figures["free"]["sink_cm"]  # the mesh's soles, not joints
    assert figures["lock"]["contacts"] == figures["lock"]["source_plants"] == 5
    legs = {k: v for k, v in role_map("own").items() if "Leg" in k or "Foot" in k or k == "Hips"}
    amap.write_text(json.dumps(legs))
    assert (
        main(
            [
                "retarget",
                "sample:walk",
                "--to",
                str(hero),
                "--out",
                str(tmp_path / "x.bvh"),
                "--map",
                str(amap),
                "-q",
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert "segue: warning:" in err and "left arm" in err and "keep their rest pose" in err
    bad = ["retarget", "sample:walk", "--to", str(hero), "--out", str(tmp_path / "y.bvh"), "--feet", "x"]
    with pytest.raises(SystemExit) as exit_:
        main(bad)
    assert exit_.value.code == 2 and "invalid choice: 'x'" in capsys.readouterr().err


def test_convert_keeps_a_motions_own_feet_on_its_floor(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plain, ground = tmp_path / "plain.bvh", tmp_path / "ground.bvh"
    assert main(["convert", "sample:walk", str(plain), "-q"]) == 0
    assert main(["convert", "sample:walk", str(tmp_path / "free.bvh"), "--feet", "free", "-q"]) == 0
    assert (tmp_path / "free.bvh").read_bytes() == plain.read_bytes()  # free: as before, the default
    assert main(["convert", "sample:walk", str(ground), "--feet", "grounding", "-q"]) == 0
    assert ground.read_bytes() != plain.read_bytes()
    assert read_bvh(ground).skeleton.names == read_bvh(plain).skeleton.names
