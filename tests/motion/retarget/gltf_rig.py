"""A skinned test character with an Unreal-style hierarchy, written as a GLB by a small glTF writer
independent of Segue's exporter.

``root`` at the floor, ``pelvis``, ``spine_01`` .. ``spine_03``, ``neck_01``, ``head``, the arms
(``clavicle_l`` .. ``hand_l``) and legs (``thigh_l``, ``calf_l``, ``foot_l``, ``ball_l``) of both
sides, plus ``ik_foot_root`` (a static child of ``root``, as in Unreal's mannequin). The joints sit
under an ``Armature`` node scaled 0.01 (joint translations in centimetres, as FBX-converted rigs
are), and every joint has its own rest orientation (its local +X along its bone, then turned about
it), so that nothing relies on identity rest rotations. The mesh is one box per bone, each vertex
bound to its bone with weight 1, with one named material.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from motion import rotations as rot
from tests.glb_writer import armature_nodes, glb

Array = npt.NDArray[np.float64]

# name, parent, world position in metres (the character faces +Z, its left is +X)
JOINTS: tuple[tuple[str, str | None, tuple[float, float, float]], ...] = (
    ("root", None, (0.0, 0.0, 0.0)),
    ("pelvis", "root", (0.0, 0.96, 0.0)),
    ("spine_01", "pelvis", (0.0, 1.06, -0.01)),
    ("spine_02", "spine_01", (0.0, 1.2, -0.01)),
    ("spine_03", "spine_02", (0.0, 1.34, -0.02)),
    ("neck_01", "spine_03", (0.0, 1.5, -0.01)),
    ("head", "neck_01", (0.0, 1.6, 0.0)),
    ("clavicle_l", "spine_03", (0.04, 1.45, 0.0)),
    ("upperarm_l", "clavicle_l", (0.19, 1.45, -0.02)),
    ("lowerarm_l", "upperarm_l", (0.46, 1.45, -0.03)),
    ("hand_l", "lowerarm_l", (0.72, 1.45, -0.02)),
    ("clavicle_r", "spine_03", (-0.04, 1.45, 0.0)),
    ("upperarm_r", "clavicle_r", (-0.19, 1.45, -0.02)),
    ("lowerarm_r", "upperarm_r", (-0.46, 1.45, -0.03)),
    ("hand_r", "lowerarm_r", (-0.72, 1.45, -0.02)),
    ("thigh_l", "pelvis", (0.1, 0.92, 0.0)),
    ("calf_l", "thigh_l", (0.1, 0.51, 0.01)),
    ("foot_l", "calf_l", (0.1, 0.09, -0.02)),
    ("ball_l", "foot_l", (0.1, 0.02, 0.12)),
    ("thigh_r", "pelvis", (-0.1, 0.92, 0.0)),
    ("calf_r", "thigh_r", (-0.1, 0.51, 0.01)),
    ("foot_r", "calf_r", (-0.1, 0.09, -0.02)),
    ("ball_r", "foot_r", (-0.1, 0.02, 0.12)),
    ("ik_foot_root", "root", (0.0, 0.0, 0.0)),
)
# where each leaf's bone (and its box) ends, metres
TIPS = {
    "head": (0.0, 1.78, 0.02),
    "hand_l": (0.88, 1.45, -0.02),
    "hand_r": (-0.88, 1.45, -0.02),
    "ball_l": (0.1, 0.01, 0.2),
    "ball_r": (-0.1, 0.01, 0.2),
}
ARMATURE_SCALE = 0.01
NAMES = tuple(j[0] for j in JOINTS)
PARENTS = tuple(-1 if p is None else NAMES.index(p) for _, p, _ in JOINTS)


def _world_rotations() -> Array:
    """``(J, 4)`` each joint's rest orientation in the world: local +X along the bone (to its
    first child or tip), then turned by a joint-specific angle about the bone."""
    pos = np.array([j[2] for j in JOINTS])
    out = []
    for k, name in enumerate(NAMES):
        kids = [c for c, p in enumerate(PARENTS) if p == k and NAMES[c] != "ik_foot_root"]
        tip = np.array(TIPS[name]) if name in TIPS else pos[kids[0]] if kids else pos[k] + [0.0, 0.0, 1.0]
        bone = tip - pos[k]
        if name == "root":
            bone = np.array([0.0, 0.0, 1.0])
        aim = rot.from_matrix(_aim_matrix(bone))
        out.append(rot.multiply(aim, rot.from_axis_angle(np.array([1.0, 0.0, 0.0]), 0.3 * k)))
    return np.array(out)


def _aim_matrix(d: Array) -> Array:
    x = d / np.linalg.norm(d)
    helper = np.array([0.0, 1.0, 0.0]) if abs(x[1]) < 0.9 else np.array([0.0, 0.0, 1.0])
    z = np.cross(x, helper)
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    return np.stack((x, y, z), axis=-1)


def _matrix(t: Array, q: Array, s: float = 1.0) -> Array:
    m = np.eye(4)
    m[:3, :3] = rot.to_matrix(q) * s
    m[:3, 3] = t
    return m


def rest_world() -> Array:
    """``(J, 4, 4)`` the joints' rest world matrices (the Armature's scale included)."""
    pos = np.array([j[2] for j in JOINTS])
    g = _world_rotations()
    return np.array([_matrix(pos[k], g[k], ARMATURE_SCALE) for k in range(len(NAMES))])


def _boxes(world: Array) -> tuple[Array, npt.NDArray[np.uint16], npt.NDArray[np.uint16]]:
    """Vertices ``(V, 3)`` (metres), joint per vertex and triangle indices of one box per bone."""
    pos = world[:, :3, 3]
    verts, joints, tris = [], [], []
    for k, name in enumerate(NAMES):
        kids = [c for c, p in enumerate(PARENTS) if p == k and NAMES[c] != "ik_foot_root"]
        ends = [pos[c] for c in kids] + ([np.array(TIPS[name])] if name in TIPS else [])
        for end in ends:
            bone = end - pos[k]
            length = float(np.linalg.norm(bone))
            if length < 1e-6 or name == "root":
                continue
            frame = _aim_matrix(bone)
            half = min(0.04, 0.2 * length)
            base = len(verts)
            for a in (0.0, length):
                for b, c in ((-half, -half), (half, -half), (half, half), (-half, half)):
                    verts.append(pos[k] + frame @ np.array([a, b, c]))
                    joints.append(k)
            quads = ((0, 1, 2, 3), (4, 7, 6, 5), (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0))
            for q in quads:
                tris += [base + q[0], base + q[1], base + q[2], base + q[0], base + q[2], base + q[3]]
    return np.array(verts), np.array(joints, dtype=np.uint16), np.array(tris, dtype=np.uint16)


def unreal_character_glb() -> bytes:
    """The test character as GLB bytes (module docstring)."""
    world = rest_world()
    g = _world_rotations()
    nodes = armature_nodes(world, g, NAMES, PARENTS, ARMATURE_SCALE, "hero_body")
    verts, joints, tris = _boxes(world)
    n = len(verts)
    joint4 = np.zeros((n, 4), np.uint16)
    joint4[:, 0] = joints
    weight4 = np.zeros((n, 4), np.float32)
    weight4[:, 0] = 1.0
    ibm = np.linalg.inv(world)
    ibm[:, 3] = [0.0, 0.0, 0.0, 1.0]
    blobs = [
        verts.astype(np.float32).tobytes(),
        joint4.tobytes(),
        weight4.tobytes(),
        tris.tobytes(),
        np.swapaxes(ibm, 1, 2).astype(np.float32).tobytes(),
    ]
    data, views = bytearray(), []
    for k, blob in enumerate(blobs):
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(data), "byteLength": len(blob)}
        if k < 3:
            view["target"] = 34962
        elif k == 3:
            view["target"] = 34963
        views.append(view)
        data += blob + b"\0" * (-len(blob) % 4)
    v32 = verts.astype(np.float32)
    accessors = [
        {"bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3",
         "min": [float(x) for x in v32.min(0)], "max": [float(x) for x in v32.max(0)]},
        {"bufferView": 1, "componentType": 5123, "count": n, "type": "VEC4"},
        {"bufferView": 2, "componentType": 5126, "count": n, "type": "VEC4"},
        {"bufferView": 3, "componentType": 5123, "count": len(tris), "type": "SCALAR"},
        {"bufferView": 4, "componentType": 5126, "count": len(NAMES), "type": "MAT4"},
    ]  # fmt: skip
    doc = {
        "asset": {"version": "2.0", "generator": "segue tests (gltf_rig.py)"},
        "scene": 0,
        "scenes": [{"name": "hero", "nodes": [0, len(nodes) - 1]}],
        "nodes": nodes,
        "skins": [{"name": "hero_skin", "joints": list(range(1, len(NAMES) + 1)), "inverseBindMatrices": 4}],
        "meshes": [
            {
                "name": "hero_body",
                "primitives": [
                    {
                        "attributes": {"POSITION": 0, "JOINTS_0": 1, "WEIGHTS_0": 2},
                        "indices": 3,
                        "material": 0,
                    }
                ],
            }
        ],
        "materials": [
            {"name": "hero_skin_material", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.5, 0.3, 1]}}
        ],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(data)}],
    }
    return glb(doc, data)


def accessor(doc: dict[str, Any], binary: bytes, index: int) -> Array:
    """The values of a float accessor (``(count, width)``)."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return (
        np.frombuffer(binary, np.float32, acc["count"] * width, start)
        .reshape(acc["count"], width)
        .astype(float)
    )


def animated_world(doc: dict[str, Any], binary: bytes, animation: int = 0) -> dict[int, Array]:
    """Node index -> ``(F, 4, 4)`` world matrices of every node with the animation's channels
    applied at each of its keys (LINEAR samplers keyed at every frame, or one key); Segue's added
    animation is the first."""
    anim = doc["animations"][animation]
    frames = max(doc["accessors"][s["input"]]["count"] for s in anim["samplers"])
    nodes = doc["nodes"]
    trs = []
    for nd in nodes:
        t = np.tile(nd.get("translation", [0.0, 0.0, 0.0]), (frames, 1)).astype(float)
        q = np.tile(nd.get("rotation", [0.0, 0.0, 0.0, 1.0]), (frames, 1)).astype(float)
        s = np.array(nd.get("scale", [1.0, 1.0, 1.0]), dtype=float)
        trs.append([t, q, s])
    for ch in anim["channels"]:
        values = accessor(doc, binary, anim["samplers"][ch["sampler"]]["output"])
        slot = {"translation": 0, "rotation": 1}[ch["target"]["path"]]
        trs[ch["target"]["node"]][slot] = np.broadcast_to(values, (frames, values.shape[1])).copy()
    parent = {c: i for i, nd in enumerate(nodes) for c in nd.get("children", [])}
    world: dict[int, Array] = {}

    def of(i: int) -> Array:
        if i not in world:
            t, q, s = trs[i]
            m = np.tile(np.eye(4), (frames, 1, 1))
            m[:, :3, :3] = rot.to_matrix(rot.normalize(q)) * s
            m[:, :3, 3] = t
            world[i] = of(parent[i]) @ m if i in parent else m
        return world[i]

    for i in range(len(nodes)):
        of(i)
    return world


def node_index(doc: dict[str, Any], name: str) -> int:
    return next(i for i, nd in enumerate(doc["nodes"]) if nd.get("name") == name)
