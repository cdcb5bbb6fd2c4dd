"""Characters from BVH and glTF/GLB files: rest poses, the skin's joints, units, bad files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from motion import MotionError, write_bvh
from motion.export.glb import write_glb
from motion.io import load_motion
from motion.retarget import retarget
from motion.retarget.character import gltf_character, load_character
from tests.glb_writer import glb

from .characters import LIMBS, angle_deg, bone_directions, character, walk


def test_bvh_character_rest_poses(tmp_path: Path) -> None:
    path = tmp_path / "char.bvh"
    write_bvh(character("mixamo"), path)
    first = load_character(path)
    zero = load_character(path, rest="zero")
    assert first.num_frames == zero.num_frames == 1 and first.units == "cm"
    assert not np.allclose(first.rotations, zero.rotations)
    np.testing.assert_allclose(zero.rotations[0, :, 3], 1.0)
    with pytest.raises(MotionError, match="rest pose 'tpose'"):
        load_character(path, rest="tpose")


def test_glb_character_matches_the_bvh_it_was_written_from(tmp_path: Path) -> None:
    src = load_motion("sample:walk-10-04").slice(0, 3)
    write_glb(src, tmp_path / "c.glb", ground_root=False, mesh=False)
    char = load_character(tmp_path / "c.glb")
    assert char.skeleton.names == src.skeleton.names and char.units == "m"
    # the GLB's rest pose is the zero-rotation pose of the offsets, in metres (wherever its root)
    rest = src.slice(0, 1).scaled(src.metres_per_unit)
    zero = np.tile([0.0, 0.0, 0.0, 1.0], (1, rest.num_joints, 1))
    expected = type(rest)(rest.skeleton, rest.root_positions, zero, 30.0).global_positions()[0]
    got = char.global_positions()[0]
    np.testing.assert_allclose(got - got[0], expected - expected[0], atol=1e-5)
    out = retarget(walk(60), char, feet="free")
    assert out.units == "m"
    assert angle_deg(bone_directions(walk(60), LIMBS), bone_directions(out, LIMBS)).max() < 0.5


def test_gltf_armature_scale_and_rotation_are_applied() -> None:
    # a DCC export: an "Armature" node scaled 0.01 and turned, joints in centimetres below it
    doc = {
        "nodes": [
            {
                "name": "Armature",
                "children": [1],
                "scale": [0.01, 0.01, 0.01],
                "rotation": [0.0, 0.7071068, 0.0, 0.7071068],
            },
            {"name": "Hips", "children": [2], "translation": [0.0, 100.0, 0.0]},
            {"name": "Spine", "translation": [0.0, 10.0, 0.0], "rotation": [0.0, 0.0, 0.3826834, 0.9238795]},
        ],
        "skins": [{"joints": [1, 2]}],
    }
    char = gltf_character(glb(doc))
    assert char.skeleton.names == ("Hips", "Spine") and char.units == "m"
    np.testing.assert_allclose(char.global_positions()[0], [[0.0, 1.0, 0.0], [0.0, 1.1, 0.0]], atol=1e-9)
    text = gltf_character(json.dumps(doc).encode())  # .gltf: plain JSON
    np.testing.assert_allclose(text.global_positions(), char.global_positions())


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        (b"glTF\x02\x00\x00\x00", "truncated GLB header"),
        (b"{not json", "not a glTF/GLB file"),
        (json.dumps({"nodes": [{"name": "a"}]}).encode(), "no skin with joints"),
        (
            json.dumps({"nodes": [{"name": "a"}, {"name": "b"}], "skins": [{"joints": [0, 1]}]}).encode(),
            "one tree",
        ),
        (json.dumps({"nodes": [{"name": "a"}], "skins": [{"joints": [5]}]}).encode(), "malformed glTF"),
    ],
)
def test_bad_gltf_files_are_named(raw: bytes, message: str) -> None:
    with pytest.raises(MotionError, match=message):
        gltf_character(raw)


def test_unreadable_character(tmp_path: Path) -> None:
    with pytest.raises(MotionError, match="cannot read the character"):
        load_character(tmp_path / "missing.glb")
