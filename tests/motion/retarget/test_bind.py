"""The retargeted animation written into the character's own glTF file (motion.export.bind): the
user's nodes, skin, mesh and materials kept, channels on the skin's joints only, and the animated
pose equal to Segue's own forward kinematics."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from motion import ExportError, MotionError
from motion.export.bind import bound_glb
from motion.io import load_motion
from motion.retarget import retarget
from motion.retarget.character import gltf_character
from tests.glb_writer import read_glb

from .gltf_rig import (
    ARMATURE_SCALE,
    NAMES,
    PARENTS,
    animated_world,
    node_index,
    unreal_character_glb,
)

FK_TOLERANCE_M = 2e-4  # float32 keys


@pytest.fixture(scope="module")
def hero() -> bytes:
    return unreal_character_glb()


@pytest.fixture(scope="module")
def walk() -> Any:
    return load_motion("sample:walk").slice(10, 130)


def _bound(hero: bytes, walk: Any, mode: str, **kw: Any) -> tuple[Any, dict[str, Any], bytes]:
    out = retarget(walk, gltf_character(hero), root_motion=mode)
    doc, binary = read_glb(bound_glb(hero, out, **kw))
    return out, doc, binary


def _fk_error(out: Any, doc: dict[str, Any], binary: bytes) -> float:
    world = animated_world(doc, binary)
    pos = out.global_positions()
    got = np.stack([world[node_index(doc, n)][:, :3, 3] for n in out.skeleton.names], axis=1)
    return float(np.abs(got - pos).max())


@pytest.mark.parametrize("mode", ["root", "hips", "none"])
def test_the_users_file_keeps_everything_and_gains_one_animation(hero: bytes, walk: Any, mode: str) -> None:
    before, before_bin = read_glb(hero)
    out, doc, binary = _bound(hero, walk, mode)
    assert [n.get("name") for n in doc["nodes"]] == [n.get("name") for n in before["nodes"]]
    for a, b in zip(doc["nodes"], before["nodes"], strict=True):
        assert a == b  # names, children, rest transforms, mesh and skin references
    for key in ("skins", "meshes", "materials", "scenes"):
        assert doc[key] == before[key]
    assert doc["accessors"][: len(before["accessors"])] == before["accessors"]
    assert binary[: len(before_bin)] == before_bin
    assert len(doc["animations"]) == 1
    joints = set(doc["skins"][0]["joints"])
    targets = {c["target"]["node"] for c in doc["animations"][0]["channels"]}
    assert targets <= joints and node_index(doc, "Armature") not in targets
    assert _fk_error(out, doc, binary) < FK_TOLERANCE_M


def test_root_motion_on_root_at_the_floor_with_the_pelvis_over_it(hero: bytes, walk: Any) -> None:
    out, doc, binary = _bound(hero, walk, "root")
    world = animated_world(doc, binary)
    root, pelvis = world[node_index(doc, "root")], world[node_index(doc, "pelvis")]
    assert np.abs(root[:, 1, 3]).max() < 1e-6  # on the floor
    assert np.abs(root[:, [0, 2], 3] - pelvis[:, [0, 2], 3]).max() < 1e-5  # the pelvis over it
    travel = np.linalg.norm(root[-1, [0, 2], 3] - root[0, [0, 2], 3])
    assert travel > 1.0  # the root carries the walk
    up = root[:, :3, :3] @ np.linalg.inv(root[0, :3, :3])
    assert np.allclose(up[:, :, 1], [0.0, 1.0, 0.0], atol=1e-5)  # it turns about +Y only
    paths = {(c["target"]["node"], c["target"]["path"]) for c in doc["animations"][0]["channels"]}
    assert (node_index(doc, "root"), "translation") in paths
    assert (node_index(doc, "pelvis"), "translation") in paths
    moved = {doc["nodes"][n]["name"] for n, p in paths if p == "translation"}
    assert moved == {"root", "pelvis"}


def test_hips_and_none_leave_the_root_at_rest(hero: bytes, walk: Any) -> None:
    for mode in ("hips", "none"):
        _, doc, binary = _bound(hero, walk, mode)
        world = animated_world(doc, binary)
        root, pelvis = world[node_index(doc, "root")], world[node_index(doc, "pelvis")]
        assert np.allclose(root, root[:1], atol=1e-6)
        horizontal = np.linalg.norm(pelvis[-1, [0, 2], 3] - pelvis[0, [0, 2], 3])
        assert (horizontal > 1.0) if mode == "hips" else (np.abs(pelvis[:, [0, 2], 3]).max() < 1e-5)


def test_animation_only_binds_by_names(hero: bytes, walk: Any) -> None:
    events = [{"type": "beat", "index": 0, "time_s": 0.5}]
    out, doc, binary = _bound(hero, walk, "root", animation_only=True, events=events)
    assert "meshes" not in doc and "materials" not in doc
    names = [n["name"] for n in doc["nodes"]]
    assert names == ["Armature", *NAMES]
    skin = doc["skins"][0]
    assert [names[j] for j in skin["joints"]] == list(NAMES)
    parent = {c: i for i, nd in enumerate(doc["nodes"]) for c in nd.get("children", [])}
    for k, name in enumerate(NAMES):
        expected = "Armature" if PARENTS[k] < 0 else NAMES[PARENTS[k]]
        assert names[parent[node_index(doc, name)]] == expected
    assert doc["nodes"][0]["scale"] == [ARMATURE_SCALE] * 3
    assert _fk_error(out, doc, binary) < FK_TOLERANCE_M
    assert doc["animations"][0]["extras"]["events"] == events
    assert doc["scenes"][0]["extras"]["events"] == events
    assert doc["nodes"][node_index(doc, "root")]["extras"]["events"] == events


def test_a_motion_of_other_joints_is_refused(hero: bytes) -> None:
    with pytest.raises(ExportError, match="not the character's skin joints"):
        bound_glb(hero, load_motion("sample:walk").slice(0, 5))


def test_root_motion_on_root_needs_a_joint_above_the_hips(walk: Any) -> None:
    mixamo_like = load_motion("sample:walk-10-04").slice(0, 1)  # starts at its hips
    with pytest.raises(MotionError, match="starts at its hips"):
        retarget(walk, mixamo_like, root_motion="root")
    with pytest.raises(MotionError, match="root motion 'feet'"):
        retarget(walk, mixamo_like, root_motion="feet")


def test_a_gltf_character_with_its_buffer_beside_it_or_inline(hero: bytes, walk: Any, tmp_path: Any) -> None:
    import base64
    import json

    doc, binary = read_glb(hero)
    (tmp_path / "hero.bin").write_bytes(binary)
    out = retarget(walk, gltf_character(hero), root_motion="root")
    for uri in ("hero.bin", "data:application/octet-stream;base64," + base64.b64encode(binary).decode()):
        text = json.dumps(dict(doc, buffers=[{"byteLength": len(binary), "uri": uri}])).encode()
        got, got_bin = read_glb(bound_glb(text, out, base_dir=tmp_path))
        assert got["nodes"] == doc["nodes"] and got_bin[: len(binary)] == binary
        assert _fk_error(out, got, got_bin) < FK_TOLERANCE_M
    with pytest.raises(ExportError, match="cannot read"):
        bound_glb(
            json.dumps(dict(doc, buffers=[{"byteLength": 4, "uri": "gone.bin"}])).encode(),
            out,
            base_dir=tmp_path,
        )


def test_the_new_animation_comes_first_so_that_importers_play_it(hero: bytes, walk: Any) -> None:
    """Blender makes a file's first animation the armature's active action: a character that
    had an idle opened playing the idle, Segue's animation stashed in an NLA track."""
    idle = retarget(walk.slice(0, 30), gltf_character(hero), root_motion="root")
    with_idle = bound_glb(hero, idle)
    out = retarget(walk, gltf_character(hero), root_motion="root")
    doc, binary = read_glb(bound_glb(with_idle, out))
    assert [a["name"] for a in doc["animations"]] == [f"{walk.name}_2", walk.name]
    assert _fk_error(out, doc, binary) < FK_TOLERANCE_M  # the first animation is the new one
