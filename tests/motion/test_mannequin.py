"""Segue's mannequin (motion/export/body.py, motion/export/mannequin.py): a closed, skinned body for
any skeleton, its soles flat on the rest floor, written as a character GLB that Segue and Blender
read like an artist's rig."""

from __future__ import annotations

import json
import struct
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from motion import rotations as rot
from motion.export.body import SkinnedMesh, body_mesh
from motion.export.glb import glb_bytes
from motion.export.mannequin import mannequin_glb, mannequin_mesh
from motion.io import load_motion
from motion.motion import Motion
from motion.retarget.character import gltf_character
from motion.retarget.names import detect_roles
from motion.skeleton import Skeleton

from .retarget.characters import character
from .retarget.gltf_rig import unreal_character_glb
from .synthetic import walking_biped

Array = npt.NDArray[np.float64]


def _rests() -> dict[str, Motion]:
    """Rest poses of skeletons of several conventions (the first frame of each)."""
    return {
        "cmu-daz walk": load_motion("sample:walk").slice(0, 1),
        "cmu-daz salsa": load_motion("sample:salsa-leader").slice(0, 1),
        "cmu start-walk-stop": load_motion("sample:start-walk-stop").slice(0, 1),
        "unreal glb": gltf_character(unreal_character_glb()),
        "mixamo": character("mixamo"),
        "unreal 1.2x": character("unreal", scale=1.2),
    }


def _edges_twice(tri: npt.NDArray[np.uint32]) -> bool:
    """Whether every edge of the triangles is used exactly twice, once in each direction (a closed,
    consistently wound surface)."""
    e = np.concatenate((tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]])).astype(np.int64)
    forward = set(map(tuple, e.tolist()))
    backward = {(b, a) for a, b in forward}
    return len(forward) == len(e) and forward == backward


@pytest.mark.parametrize("name", list(_rests()))
def test_the_body_is_closed_outward_and_skinned_with_weights_summing_to_one(name: str) -> None:
    rest = _rests()[name]
    body = mannequin_mesh(rest)
    j = rest.num_joints
    assert body.positions.shape == body.normals.shape == (body.num_vertices, 3)
    assert body.joints.shape == body.weights.shape == (body.num_vertices, 4)
    assert body.joints.max() < j and body.weights.min() >= 0.0
    assert np.allclose(body.weights.sum(axis=1), 1.0, atol=1e-6)
    assert np.allclose(np.linalg.norm(body.normals, axis=1), 1.0, atol=1e-6)
    assert _edges_twice(body.indices)
    p = body.positions[body.indices.astype(np.intp)]
    volume = float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum()) / 6.0
    height = float(np.ptp(body.positions[:, 1]))
    assert 0.006 * height**3 < volume < 0.03 * height**3  # a person (0.065 m³ at 1.75 m): wound outwards


@pytest.mark.parametrize("name", list(_rests()))
def test_each_sole_is_flat_on_the_floor_from_a_heel_behind_the_ankle_to_the_toe_tip(name: str) -> None:
    rest = _rests()[name]
    body = mannequin_mesh(rest)
    pos = rest.global_positions()[0] * rest.metres_per_unit
    ends = rest.end_site_positions()[0] * rest.metres_per_unit
    floor = float(min(pos[:, 1].min(), ends[:, 1].min() if ends.size else np.inf))
    assert body.positions[:, 1].min() >= floor - 1e-9  # nothing under the floor
    roles = detect_roles(rest.skeleton).joints
    for side in ("Left", "Right"):
        foot = [roles[f"{side}Foot"]] + ([roles[f"{side}Toes"]] if f"{side}Toes" in roles else [])
        mine = np.isin(body.joints[:, 0], foot) & (body.weights[:, 0] > 0.5)
        sole = body.positions[mine & (body.positions[:, 1] < floor + 1e-6)]
        assert len(sole) >= 8, f"{side} foot: {len(sole)} sole vertices on the floor"
        ankle = pos[roles[f"{side}Foot"]]
        flat = (sole - ankle)[:, [0, 2]]
        toe = flat[np.argmax(np.linalg.norm(flat, axis=1))]
        ahead = toe / np.linalg.norm(toe)
        along, across = flat @ ahead, flat @ np.array([-ahead[1], ahead[0]])
        assert along.min() < -0.03 and along.max() > 0.1  # heel behind the ankle, toes ahead (m)
        assert np.ptp(across) > 0.04  # a sole, not a line (m)


def _skinned(body: SkinnedMesh, rest: Motion, posed: Motion, frame: int) -> Array:
    """Linear-blend skinning of the body (bound in ``rest``'s pose) into ``posed``'s ``frame``."""

    def matrices(m: Motion, f: int) -> Array:
        pos, grot = m.fk()
        out = np.tile(np.eye(4), (m.num_joints, 1, 1))
        out[:, :3, :3] = rot.to_matrix(grot[f])
        out[:, :3, 3] = pos[f] * m.metres_per_unit
        return out

    skin = matrices(posed, frame) @ np.linalg.inv(matrices(rest, 0))
    homo = np.concatenate((body.positions, np.ones((body.num_vertices, 1))), axis=1)
    moved = np.einsum("vkab,vb->vka", skin[body.joints.astype(np.intp)], homo)[..., :3]
    return np.asarray(np.einsum("vk,vka->va", body.weights, moved))


def test_the_body_follows_its_bones_through_a_walk_without_tearing() -> None:
    walk = load_motion("sample:walk")
    rest = walk.slice(0, 1)
    body = mannequin_mesh(rest)
    edges = np.concatenate((body.indices[:, [0, 1]], body.indices[:, [1, 2]])).astype(np.intp)
    rest_len = np.linalg.norm(np.diff(body.positions[edges], axis=1)[:, 0], axis=1)
    pos = walk.global_positions() * walk.metres_per_unit
    for f in (10, 40, 70):
        v = _skinned(body, rest, walk, f)
        length = np.linalg.norm(np.diff(v[edges], axis=1)[:, 0], axis=1)
        assert np.max(length - rest_len) < 0.06  # no edge stretched by more than 6 cm (m)
        dist = np.linalg.norm(v[:, None] - pos[f][None], axis=-1).min(axis=1)
        assert dist.max() < 0.25  # every vertex near the skeleton (m)


def test_a_skeleton_whose_roles_are_unknown_gets_a_capsule_per_bone() -> None:
    walk = load_motion("sample:walk").slice(0, 1)
    sk = walk.skeleton
    odd = Skeleton(
        tuple(f"bone{k}" for k in range(sk.num_joints)),
        sk.parents,
        sk.offsets,
        sk.channels,
        sk.end_site_parents,
        sk.end_site_offsets,
    )
    pos = walk.global_positions()[0] * walk.metres_per_unit
    body = body_mesh(odd, pos, walk.end_site_positions()[0] * walk.metres_per_unit)
    assert _edges_twice(body.indices)
    assert np.allclose(body.weights.sum(axis=1), 1.0, atol=1e-6)
    assert len(np.unique(body.joints[:, 0])) > 0.6 * sk.num_joints  # most bones carry a capsule


def _read(raw: bytes) -> tuple[dict[str, Any], bytes]:
    n = struct.unpack_from("<I", raw, 12)[0]
    return json.loads(raw[20 : 20 + n]), raw[20 + n + 8 :]


def test_mannequin_glb_is_a_character_under_names_of_its_own_that_retargeting_reads() -> None:
    rest = load_motion("sample:walk-10-04")
    own = [f"rig_{n.lower()}" for n in rest.skeleton.names]
    raw = mannequin_glb(rest, names=own)
    doc, _ = _read(raw)
    assert "animations" not in doc  # a character, not a clip
    (mesh,) = doc["meshes"]
    assert mesh["name"].endswith("_body") and doc["materials"][0]["name"] == "body"
    read = gltf_character(raw)
    assert list(read.skeleton.names) == own
    assert np.array_equal(read.skeleton.parents, rest.skeleton.parents)
    pos = read.global_positions()[0]
    assert 0.0 <= float(pos[:, 1].min()) < 0.1  # standing on the floor (its toe tips at 0)
    assert float(np.ptp(pos[:, 1])) > 1.2  # a standing person, metres


def test_any_export_can_wear_the_body_and_a_crowd_shares_one_body_mesh() -> None:
    walk = walking_biped(frames=20)
    raw = glb_bytes(walk, mesh="body")
    doc, _ = _read(raw)
    assert doc["meshes"][0]["name"].endswith("_body")
    with pytest.raises(Exception, match="unknown mesh"):
        glb_bytes(walk, mesh="skin")  # type: ignore[arg-type]
