"""Tests of :mod:`motion.export.glb`: container validity and an independent re-animation of the file."""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

import motion
from motion import rotations as rot
from motion.errors import ExportError
from motion.export.glb import glb_bytes, write_glb
from motion.samples import sample_path

Array = npt.NDArray[np.float64]

TOL_M = 1e-5
COMPONENTS = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


# ------------------------------------------------------------------------------------------------
# a small independent GLB reader
# ------------------------------------------------------------------------------------------------


@dataclass
class Glb:
    gltf: dict[str, Any]
    binary: bytes

    def accessor(self, index: int) -> Array:
        """``(count, width)`` values of an accessor (``(count, 4, 4)`` matrices for MAT4, column-major)."""
        acc = self.gltf["accessors"][index]
        view = self.gltf["bufferViews"][acc["bufferView"]]
        dtype = np.dtype(COMPONENTS[acc["componentType"]])
        width = WIDTH[acc["type"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        assert "byteStride" not in view or view["byteStride"] == width * dtype.itemsize
        raw = np.frombuffer(self.binary, dtype=dtype, count=acc["count"] * width, offset=start)
        out = raw.astype(np.float64).reshape(acc["count"], width)
        if acc["type"] == "MAT4":
            return np.swapaxes(out.reshape(-1, 4, 4), 1, 2)  # column-major storage
        return out


def read_glb(data: bytes) -> Glb:
    """Parse and validate the container and the buffer/accessor layout of a GLB file."""
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF"
    assert version == 2
    assert length == len(data)
    assert length % 4 == 0
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A
    assert json_len % 4 == 0
    text = data[20 : 20 + json_len]
    assert text.rstrip(b" ").endswith(b"}")  # padded with spaces only
    gltf = json.loads(text.decode("utf-8"))
    pos = 20 + json_len
    bin_len, bin_type = struct.unpack_from("<II", data, pos)
    assert bin_type == 0x004E4942
    assert bin_len % 4 == 0
    binary = data[pos + 8 : pos + 8 + bin_len]
    assert pos + 8 + bin_len == length

    assert gltf["asset"] == {"version": "2.0", "generator": "segue"}
    (buffer,) = gltf["buffers"]
    assert "uri" not in buffer
    assert buffer["byteLength"] <= bin_len <= buffer["byteLength"] + 3
    assert binary[buffer["byteLength"] :] == b"\0" * (bin_len - buffer["byteLength"])
    for view in gltf["bufferViews"]:
        assert view["buffer"] == 0
        assert view.get("byteOffset", 0) % 4 == 0
        assert view.get("byteOffset", 0) + view["byteLength"] <= buffer["byteLength"]
    for index, acc in enumerate(gltf["accessors"]):
        view = gltf["bufferViews"][acc["bufferView"]]
        size = np.dtype(COMPONENTS[acc["componentType"]]).itemsize
        offset = acc.get("byteOffset", 0)
        assert offset % size == 0
        assert offset % 4 == 0
        assert acc["count"] >= 1
        assert offset + acc["count"] * WIDTH[acc["type"]] * size <= view["byteLength"]
        if "min" in acc or "max" in acc:
            values = Glb(gltf, binary).accessor(index)
            assert len(acc["min"]) == len(acc["max"]) == WIDTH[acc["type"]]
            np.testing.assert_array_equal(values.min(axis=0), np.float32(acc["min"]))
            np.testing.assert_array_equal(values.max(axis=0), np.float32(acc["max"]))
    return Glb(gltf, binary)


# ------------------------------------------------------------------------------------------------
# fixtures
# ------------------------------------------------------------------------------------------------


def synthetic_motion() -> motion.Motion:
    """Three joints (root, bent chain) with an End Site, 25 frames, in centimetres, and rotations that
    cross the quaternion sign boundary."""
    sk = motion.Skeleton(
        ("pelvis", "spine", "head"),
        np.array([-1, 0, 1]),
        np.array([[0.0, 90.0, 0.0], [0.0, 30.0, 5.0], [10.0, 25.0, 0.0]]),
        (
            ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),
            ("Zrotation", "Yrotation", "Xrotation"),
            ("Zrotation", "Yrotation", "Xrotation"),
        ),
        np.array([2]),
        np.array([[0.0, 12.0, 0.0]]),
    )
    f = 25
    t = np.arange(f) / 30.0
    angles = np.stack(
        (
            np.stack((20 * np.sin(t), 350 * t, 10 * np.cos(2 * t)), axis=-1),
            np.stack((40 * np.sin(3 * t), 15 * t, -25 * t), axis=-1),
            np.stack((-30 * t, 60 * np.sin(t), 5 * t), axis=-1),
        ),
        axis=1,
    )
    q = rot.from_euler("ZYX", angles)
    q[1::3] *= -1.0  # same rotations, scrambled signs: the exporter must make them continuous
    root = np.stack((100 * t, 90 + 3 * np.sin(5 * t), -40 * t), axis=-1)
    return motion.Motion(sk, root, q, fps=30.0, units="cm", name="synthetic")


@pytest.fixture(scope="module")
def walk() -> motion.Motion:
    return motion.read_bvh(sample_path("walk")).slice(0, 60)


# ------------------------------------------------------------------------------------------------
# re-animation with plain 4x4 matrices
# ------------------------------------------------------------------------------------------------


def trs_matrix(t: Array, q: Array, s: Array) -> Array:
    x, y, z, w = q
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    m = np.eye(4)
    m[:3, :3] = r * s[None, :]
    m[:3, 3] = t
    return m


def node_globals(glb: Glb, frame: int | None) -> Array:
    """``(N, 4, 4)`` global matrices of every node at a key frame (``None``: rest pose), every
    animation applied (a crowd has one per character, on disjoint nodes)."""
    gltf = glb.gltf
    nodes = gltf["nodes"]
    animated: dict[tuple[int, str], Array] = {}
    for anim in gltf["animations"] if frame is not None else []:
        for ch in anim["channels"]:
            sampler = anim["samplers"][ch["sampler"]]
            assert sampler["interpolation"] == "LINEAR"
            values = glb.accessor(sampler["output"])  # one key: the value of every frame
            assert (ch["target"]["node"], ch["target"]["path"]) not in animated
            animated[ch["target"]["node"], ch["target"]["path"]] = values[min(frame, len(values) - 1)]
    local = np.empty((len(nodes), 4, 4))
    for i, node in enumerate(nodes):
        if "matrix" in node:
            local[i] = np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
            continue
        t = animated.get((i, "translation"), np.array(node.get("translation", [0.0, 0.0, 0.0])))
        q = animated.get((i, "rotation"), np.array(node.get("rotation", [0.0, 0.0, 0.0, 1.0])))
        s = animated.get((i, "scale"), np.array(node.get("scale", [1.0, 1.0, 1.0])))
        local[i] = trs_matrix(t, q, s)
    out = np.full((len(nodes), 4, 4), np.nan)
    stack = [(root, np.eye(4)) for root in gltf["scenes"][gltf.get("scene", 0)]["nodes"]]
    while stack:
        i, parent = stack.pop()
        assert np.isnan(out[i, 0, 0]), f"node {i} reached twice"
        out[i] = parent @ local[i]
        stack.extend((c, out[i]) for c in nodes[i].get("children", []))
    return out


def check_file(data: bytes, m: motion.Motion, *, ground: bool, mesh: bool = True) -> Glb:
    glb = read_glb(data)
    gltf = glb.gltf
    nodes = gltf["nodes"]
    sk = m.skeleton
    scale = m.metres_per_unit

    # skin
    (skin,) = gltf["skins"]
    joints = skin["joints"]
    ibm = glb.accessor(skin["inverseBindMatrices"])
    assert len(joints) == ibm.shape[0] == gltf["accessors"][skin["inverseBindMatrices"]]["count"]
    assert len(joints) == sk.num_joints + (1 if ground else 0)
    assert skin["skeleton"] in gltf["scenes"][0]["nodes"]
    names = [nodes[j]["name"] for j in joints]
    assert names[: 1 if ground else 0] == (["ground"] if ground else [])
    assert names[1 if ground else 0 :] == list(sk.names)
    assert nodes[skin["skeleton"]]["name"] == names[0]
    rest = node_globals(glb, None)
    np.testing.assert_allclose(ibm @ rest[joints], np.broadcast_to(np.eye(4), ibm.shape), atol=1e-6)

    # animation: one shared time input, key times frame / fps
    (anim,) = gltf["animations"]
    assert anim["name"] == (m.name or "motion")
    inputs = {s["input"] for s in anim["samplers"]}
    assert 1 <= len(inputs) <= 2  # every frame, and one key for channels that never change
    t_acc = max(inputs, key=lambda i: gltf["accessors"][i]["count"])
    times = glb.accessor(t_acc)[:, 0]
    np.testing.assert_allclose(times, np.arange(m.num_frames) / m.fps, atol=1e-6)
    for s in anim["samplers"]:
        count = gltf["accessors"][s["input"]]["count"]
        assert gltf["accessors"][s["output"]]["count"] == count
        assert s["input"] == t_acc or (count == 1 and glb.accessor(s["input"])[0, 0] == 0.0)
    targets = {(c["target"]["node"], c["target"]["path"]) for c in anim["channels"]}
    assert len(targets) == len(anim["channels"])
    assert {(j, "rotation") for j in joints} <= targets
    assert (joints[0], "translation") in targets
    for s, c in zip(anim["samplers"], anim["channels"], strict=True):
        if c["target"]["path"] == "rotation":
            q = glb.accessor(s["output"])
            np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
            assert np.all(np.sum(q[1:] * q[:-1], axis=1) >= 0.0), "quaternion signs are not continuous"

    # re-animate several frames: joint positions match the motion's FK in metres
    expected = m.global_positions() * scale
    end_expected = m.end_site_positions() * scale
    end_nodes = [i for i, n in enumerate(nodes) if n["name"].endswith("_end") and i not in joints]
    assert len(end_nodes) == sk.end_site_parents.size
    frames = sorted({0, 1, m.num_frames // 3, m.num_frames // 2, m.num_frames - 1} & set(range(m.num_frames)))
    for f in frames:
        g = node_globals(glb, f)
        positions = g[joints[1 if ground else 0 :], :3, 3]
        np.testing.assert_allclose(positions, expected[f], atol=TOL_M, rtol=0)
        np.testing.assert_allclose(g[end_nodes, :3, 3], end_expected[f], atol=TOL_M, rtol=0)
        if ground:
            assert abs(g[joints[0], 1, 3]) < 1e-9  # the ground root stays on the floor
        if mesh:
            check_skinned_mesh(glb, g, rest, expected[f], m)
    return glb


def check_skinned_mesh(glb: Glb, g: Array, rest: Array, joints_m: Array, m: motion.Motion) -> None:
    """Skin the bone mesh at one frame (node globals ``g``, rest-pose node globals ``rest``, the
    motion's joint positions ``joints_m`` in metres): every vertex that sits on a joint or End Site
    in the rest pose lands on it, and every drawn bone's tip lands on its child joint."""
    gltf = glb.gltf
    joints = gltf["skins"][0]["joints"]
    ibm = glb.accessor(gltf["skins"][0]["inverseBindMatrices"])
    skin_matrices = g[joints] @ ibm
    mesh_nodes = [i for i, n in enumerate(gltf["nodes"]) if "mesh" in n]
    assert len(mesh_nodes) == 1
    node = gltf["nodes"][mesh_nodes[0]]
    assert node["skin"] == 0
    assert node["mesh"] == 0
    assert not {"translation", "rotation", "scale", "matrix"} & node.keys()
    assert mesh_nodes[0] in gltf["scenes"][0]["nodes"]
    assert all(mesh_nodes[0] not in n.get("children", []) for n in gltf["nodes"])
    (prim,) = gltf["meshes"][0]["primitives"]
    assert prim["material"] < len(gltf["materials"])
    attrs = prim["attributes"]
    acc = gltf["accessors"]
    assert acc[attrs["JOINTS_0"]]["componentType"] == 5123
    assert acc[attrs["JOINTS_0"]]["type"] == acc[attrs["WEIGHTS_0"]]["type"] == "VEC4"
    assert acc[attrs["WEIGHTS_0"]]["componentType"] == 5126
    assert acc[prim["indices"]]["componentType"] in (5123, 5125)
    pos = glb.accessor(attrs["POSITION"])
    normals = glb.accessor(attrs["NORMAL"])
    jnt = glb.accessor(attrs["JOINTS_0"]).astype(np.intp)
    wgt = glb.accessor(attrs["WEIGHTS_0"])
    idx = glb.accessor(prim["indices"])[:, 0].astype(np.intp)
    n = pos.shape[0]
    assert normals.shape[0] == jnt.shape[0] == wgt.shape[0] == n
    assert idx.size % 3 == 0
    assert idx.max() < n
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(wgt.sum(axis=1), 1.0, atol=1e-6)
    assert jnt.max() < skin_matrices.shape[0]
    # triangles are counter-clockwise seen from outside: face normal agrees with the stored normal
    tri = pos[idx].reshape(-1, 3, 3)
    face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.sum(face * normals[idx[::3]], axis=1) > 0)
    # linear blend skinning
    homo = np.concatenate((pos, np.ones((n, 1))), axis=1)
    per_joint = np.einsum("jab,vb->vja", skin_matrices, homo)[..., :3]  # (V, J, 3)
    skinned = np.einsum("vk,vka->va", wgt, per_joint[np.arange(n)[:, None], jnt])
    # vertices on a joint or End Site in the rest pose follow it (a mis-bound vertex would not)
    anim_nodes = {
        c["target"]["node"] for c in gltf["animations"][0]["channels"] if c["target"]["path"] == "translation"
    }
    markers = [i for i, nd in enumerate(gltf["nodes"]) if i in joints or nd["name"].endswith("_end")]
    rest_pos = rest[markers, :3, 3]
    on = np.linalg.norm(pos[:, None] - rest_pos[None], axis=-1) < 1e-6  # (V, markers)
    moved = np.array([i in anim_nodes and i != joints[0] for i in markers])
    checked = on.any(axis=1) & ~(on & moved[None]).any(axis=1)
    assert checked.sum() >= 2 * len(gltf["nodes"]) // 3
    err = np.linalg.norm(skinned[:, None] - g[markers, :3, 3][None], axis=-1)
    ok = (on & (err < TOL_M)).any(axis=1)
    assert np.all(ok[checked]), f"{np.sum(~ok[checked])} skinned vertices left their joint"
    sk = m.skeleton
    offsets = sk.offsets * m.metres_per_unit
    for j in range(1, sk.num_joints):
        ground_link = sk.parents[j] == 0 and sk.names[0] == "ground"  # not drawn
        if np.linalg.norm(offsets[j]) < 1e-6 or ground_link or j in sk.translated_joints:
            continue
        d = np.linalg.norm(skinned - joints_m[j], axis=1).min()
        assert d < TOL_M, f"no skinned vertex at joint {sk.names[j]} (nearest {d:.2e} m)"


# ------------------------------------------------------------------------------------------------
# tests
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("ground", [True, False])
def test_synthetic_motion_reanimates(ground: bool) -> None:
    m = synthetic_motion()
    check_file(glb_bytes(m, ground_root=ground), m, ground=ground)


@pytest.mark.parametrize("ground", [True, False])
def test_walk_sample_reanimates(walk: motion.Motion, ground: bool) -> None:
    check_file(glb_bytes(walk, ground_root=ground), walk, ground=ground)


def test_without_mesh(walk: motion.Motion) -> None:
    glb = check_file(glb_bytes(walk, mesh=False), walk, ground=True, mesh=False)
    assert "meshes" not in glb.gltf
    assert glb.gltf["scenes"][0]["nodes"] == [0]


def test_ground_root_false_keeps_joint_count(walk: motion.Motion) -> None:
    glb = read_glb(glb_bytes(walk, ground_root=False))
    (skin,) = glb.gltf["skins"]
    assert len(skin["joints"]) == walk.num_joints
    assert "ground" not in {n["name"] for n in glb.gltf["nodes"]}
    grounded = read_glb(glb_bytes(walk))
    assert len(grounded.gltf["skins"][0]["joints"]) == walk.num_joints + 1


def test_existing_ground_root_is_not_added_twice(walk: motion.Motion) -> None:
    from motion.ground import add_ground_root

    g = add_ground_root(walk)
    glb = check_file(glb_bytes(g), g, ground=False)
    assert len(glb.gltf["skins"][0]["joints"]) == walk.num_joints + 1


def test_units_become_metres() -> None:
    m = synthetic_motion()
    in_m = read_glb(glb_bytes(m.to_units("m")))
    in_cm = read_glb(glb_bytes(m))
    assert in_m.gltf["nodes"][:4] == in_cm.gltf["nodes"][:4]
    unknown = m.with_units("unknown")
    check_file(glb_bytes(unknown), unknown, ground=True)  # written as if in metres


def test_single_frame() -> None:
    m = synthetic_motion().slice(0, 1)
    check_file(glb_bytes(m), m, ground=True)


def test_write_glb_matches_bytes(tmp_path: Path, walk: motion.Motion) -> None:
    dest = tmp_path / "walk.glb"
    write_glb(walk, dest)
    assert dest.read_bytes() == glb_bytes(walk)
    write_glb(walk, str(dest), ground_root=False, mesh=False)
    assert dest.read_bytes() == glb_bytes(walk, ground_root=False, mesh=False)


def test_zero_frames_raise() -> None:
    m = synthetic_motion()
    empty = motion.Motion(m.skeleton, np.zeros((0, 3)), np.zeros((0, 3, 4)), fps=30.0)
    with pytest.raises(ExportError, match="no frames"):
        glb_bytes(empty)


def test_non_finite_values_raise() -> None:
    m = synthetic_motion()
    root = m.root_positions.copy()
    root[3, 1] = np.nan
    bad = motion.Motion(m.skeleton, root, m.rotations, fps=m.fps, units=m.units)
    with pytest.raises(ExportError, match="non-finite"):
        glb_bytes(bad)


def test_unwritable_path_raises(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match="cannot write"):
        write_glb(synthetic_motion(), tmp_path / "missing" / "out.glb")
