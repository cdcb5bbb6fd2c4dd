"""Export conventions, NPZ and JSON frames, and the by-extension I/O."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from motion import ExportError, MotionError, read_bvh
from motion.export.arrays import motion_json, npz_bytes
from motion.export.targets import get_target, to_target, transform_points
from motion.io import load_motion, save_motion

from .synthetic import walking_biped


def test_target_bases_map_axes_as_documented() -> None:
    up, forward, left = np.eye(3)[1], np.eye(3)[2], np.eye(3)[0]
    unreal = get_target("unreal")
    # Unreal: Z up, X forward, Y right (so the body's left is -Y), centimetres
    np.testing.assert_allclose(transform_points(up, unreal, 1.0), [0, 0, 100])
    np.testing.assert_allclose(transform_points(forward, unreal, 1.0), [100, 0, 0])
    np.testing.assert_allclose(transform_points(left, unreal, 1.0), [0, -100, 0])
    unity = get_target("unity")
    np.testing.assert_allclose(transform_points(left, unity, 1.0), [-1, 0, 0])
    assert np.linalg.det(unreal.basis) == pytest.approx(-1.0)
    with pytest.raises(ExportError):
        get_target("blender")


@pytest.mark.parametrize("target", ["gltf", "godot", "unity", "unreal"])
def test_to_target_moves_global_positions(target: str) -> None:
    m = walking_biped(frames=20)
    moved = to_target(m, target)
    tgt = get_target(target)
    np.testing.assert_allclose(
        moved.global_positions(), transform_points(m.global_positions(), tgt, 1.0), atol=1e-10
    )
    assert moved.units == tgt.units


def test_npz_contents(tmp_path: Path) -> None:
    m = walking_biped(frames=15).to_units("cm")
    path = tmp_path / "m.npz"
    path.write_bytes(npz_bytes(m))
    z = np.load(path, allow_pickle=False)
    assert [str(n) for n in z["names"]] == list(m.skeleton.names)
    np.testing.assert_allclose(z["positions"], m.global_positions())  # the file's own numbers
    assert float(z["fps"]) == 30.0 and str(z["units"]) == "cm"
    np.testing.assert_array_equal(z["parents"], m.skeleton.parents)
    z2 = np.load(__import__("io").BytesIO(npz_bytes(m, units="m")), allow_pickle=False)
    np.testing.assert_allclose(z2["positions"], m.global_positions() / 100)  # the override
    assert str(z2["units"]) == "m"
    z3 = np.load(__import__("io").BytesIO(npz_bytes(m, "unreal")), allow_pickle=False)
    assert str(z3["units"]) == "cm"


def test_json_frames_are_valid_and_consistent() -> None:
    m = walking_biped(frames=12)
    doc = json.loads(json.dumps(motion_json(m, "unreal")))
    assert doc["frame_count"] == 12 and len(doc["frames"]) == 12
    assert doc["convention"]["units"] == "cm"
    pos = np.array(doc["frames"][5]["positions"])
    np.testing.assert_allclose(
        pos, transform_points(m.global_positions()[5], get_target("unreal"), 1.0), atol=1e-4
    )
    q = np.array(doc["frames"][5]["rotations"])
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-5)


def test_save_and_load_by_extension(tmp_path: Path) -> None:
    m = walking_biped(frames=25)
    for name in ("a.bvh", "a.bvh.gz", "a.npz", "a.json", "a.glb"):
        notes = save_motion(m, tmp_path / name)
        assert notes == []
        assert (tmp_path / name).stat().st_size > 0
    back = load_motion(tmp_path / "a.bvh.gz", units="m")
    np.testing.assert_allclose(back.global_positions(), m.global_positions(), atol=2e-6)
    unreal_bvh = tmp_path / "u.bvh"
    save_motion(m, unreal_bvh, target="unreal")
    u = read_bvh(unreal_bvh, units="cm")
    np.testing.assert_allclose(
        u.global_positions(), transform_points(m.global_positions(), get_target("unreal"), 1.0), atol=1e-3
    )
    assert save_motion(m, tmp_path / "b.glb", target="unity")  # a note: GLB stays glTF
    with pytest.raises(MotionError):
        save_motion(m, tmp_path / "a.fbx")
    with pytest.raises(MotionError):
        load_motion(tmp_path / "a.npz")
