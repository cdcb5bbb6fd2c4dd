"""A held-out skinned character for the browser tests, written as a GLB by a small glTF writer of its
own (nothing in Segue made it, and nothing in Segue was tuned to it).

Mixamo joint names (``mixamorig:Hips``, ``mixamorig:LeftUpLeg``...), 1.85 m tall with long legs,
standing in an A-pose (arms 40 degrees down, not Segue's T-pose), its joints in centimetres under
an ``Armature`` node scaled 0.01 and each turned about its bone (no identity rest rotations). The
mesh is an eight-sided tube per bone (tapered; rounder for the head) with outward normals, each
vertex bound to its bone,
in two primitives with two named materials: ``skin`` (head, neck, hands) and ``suit`` (the rest).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from motion import rotations as rot
from tests.glb_writer import armature_nodes, glb

Array = npt.NDArray[np.float64]
P = "mixamorig:"
_DOWN = np.radians(40.0)  # the arms' angle below horizontal
_ARM = (np.cos(_DOWN), -np.sin(_DOWN))


def _arm(side: float, reach: float) -> tuple[float, float, float]:
    return (side * (0.2 + reach * _ARM[0]), 1.5 + reach * _ARM[1], -0.02)


# name, parent, world position (metres; facing +Z, its left is +X), tube radius (m)
JOINTS: tuple[tuple[str, str | None, tuple[float, float, float], float], ...] = (
    ("Hips", None, (0.0, 1.02, 0.0), 0.15),
    ("Spine", "Hips", (0.0, 1.12, -0.01), 0.14),
    ("Spine1", "Spine", (0.0, 1.26, -0.01), 0.15),
    ("Spine2", "Spine1", (0.0, 1.4, -0.02), 0.16),
    ("Neck", "Spine2", (0.0, 1.56, -0.02), 0.06),
    ("Head", "Neck", (0.0, 1.66, 0.0), 0.1),
    ("LeftShoulder", "Spine2", (0.06, 1.5, -0.02), 0.06),
    ("LeftArm", "LeftShoulder", (0.2, 1.5, -0.02), 0.055),
    ("LeftForeArm", "LeftArm", _arm(1, 0.3), 0.045),
    ("LeftHand", "LeftForeArm", _arm(1, 0.57), 0.04),
    ("RightShoulder", "Spine2", (-0.06, 1.5, -0.02), 0.06),
    ("RightArm", "RightShoulder", (-0.2, 1.5, -0.02), 0.055),
    ("RightForeArm", "RightArm", _arm(-1, 0.3), 0.045),
    ("RightHand", "RightForeArm", _arm(-1, 0.57), 0.04),
    ("LeftUpLeg", "Hips", (0.1, 0.97, 0.0), 0.08),
    ("LeftLeg", "LeftUpLeg", (0.1, 0.53, 0.01), 0.06),
    ("LeftFoot", "LeftLeg", (0.1, 0.09, -0.02), 0.045),
    ("LeftToeBase", "LeftFoot", (0.1, 0.025, 0.13), 0.04),
    ("RightUpLeg", "Hips", (-0.1, 0.97, 0.0), 0.08),
    ("RightLeg", "RightUpLeg", (-0.1, 0.53, 0.01), 0.06),
    ("RightFoot", "RightLeg", (-0.1, 0.09, -0.02), 0.045),
    ("RightToeBase", "RightFoot", (-0.1, 0.025, 0.13), 0.04),
)
TIPS = {
    "Head": (0.0, 1.85, 0.01),
    "LeftHand": _arm(1, 0.75),
    "RightHand": _arm(-1, 0.75),
    "LeftToeBase": (0.1, 0.025, 0.21),
    "RightToeBase": (-0.1, 0.025, 0.21),
}
SKIN = {"Head", "Neck", "LeftHand", "RightHand"}
PROFILES = {  # rings along a bone: (fraction of its length, fraction of its radius)
    "Head": ((0.0, 0.55), (0.2, 0.9), (0.55, 1.0), (0.85, 0.8), (1.0, 0.3)),
    "Hips": ((0.0, 1.0), (1.0, 0.9)),
}
LIMB = ((0.0, 1.0), (0.5, 0.95), (1.0, 0.78))
NAMES = tuple(P + j[0] for j in JOINTS)
PARENTS = tuple(-1 if p is None else [j[0] for j in JOINTS].index(p) for _, p, _, _ in JOINTS)
ARMATURE_SCALE = 0.01
SIDES = 8


def _frame(d: Array) -> Array:
    """Columns (bone, side, other side): an orthonormal frame whose first axis is along ``d``."""
    x = d / np.linalg.norm(d)
    helper = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(helper, x)
    y /= np.linalg.norm(y)
    return np.stack((x, y, np.cross(x, y)), axis=-1)


def _world() -> tuple[Array, Array]:
    """Joint positions ``(J, 3)`` and rest world orientations ``(J, 4)`` (bone along +X, turned)."""
    pos = np.array([j[2] for j in JOINTS])
    out = []
    for k, (name, *_rest) in enumerate(JOINTS):
        kids = [c for c, p in enumerate(PARENTS) if p == k]
        tip = np.array(TIPS[name]) if name in TIPS else pos[kids[0]]
        aim = rot.from_matrix(_frame(tip - pos[k]))
        out.append(rot.multiply(aim, rot.from_axis_angle(np.array([1.0, 0.0, 0.0]), 0.5 + 0.2 * k)))
    return pos, np.array(out)


def _tubes() -> dict[str, tuple[Array, Array, npt.NDArray[np.uint16], npt.NDArray[np.uint16]]]:
    """Per material: vertices ``(V, 3)`` metres, normals, joint per vertex, triangle indices."""
    pos, _ = _world()
    parts: dict[str, tuple[list[Array], list[Array], list[int], list[int]]] = {
        "skin": ([], [], [], []),
        "suit": ([], [], [], []),
    }
    for k, (name, _parent, _p, radius) in enumerate(JOINTS):
        kids = [c for c, p in enumerate(PARENTS) if p == k]
        ends = [np.array(TIPS[name])] if name in TIPS else [pos[c] for c in kids]
        if name == "Hips":
            ends = [
                pos[NAMES.index(P + "Spine")],
                pos[NAMES.index(P + "LeftUpLeg")],
                pos[NAMES.index(P + "RightUpLeg")],
            ]
        verts, norms, joints, tris = parts["skin" if name in SKIN else "suit"]
        profile = PROFILES.get(name, LIMB)
        for end in ends:
            f = _frame(end - pos[k])
            length = float(np.linalg.norm(end - pos[k]))
            base = len(verts)
            for a, r in profile:
                for s in range(SIDES):
                    t = 2 * np.pi * s / SIDES
                    radial = f @ np.array([0.0, np.cos(t), np.sin(t)])
                    verts.append(pos[k] + f[:, 0] * a * length + radial * r * radius)
                    norms.append(radial)
                    joints.append(k)
            for ring in range(len(profile) - 1):
                lo, hi = base + ring * SIDES, base + (ring + 1) * SIDES
                for s in range(SIDES):
                    a0, a1, b0, b1 = lo + s, lo + (s + 1) % SIDES, hi + s, hi + (s + 1) % SIDES
                    tris += [a0, b0, a1, a1, b0, b1]
            last = base + (len(profile) - 1) * SIDES
            for a, sign, ring in ((0.0, -1.0, base), (length, 1.0, last)):  # caps
                centre = len(verts)
                verts.append(pos[k] + f[:, 0] * a)
                norms.append(sign * f[:, 0])
                joints.append(k)
                for s in range(SIDES):
                    q0, q1 = ring + s, ring + (s + 1) % SIDES
                    tris += [centre, q1, q0] if sign > 0 else [centre, q0, q1]
    return {
        m: (np.array(v), np.array(n), np.array(j, dtype=np.uint16), np.array(t, dtype=np.uint16))
        for m, (v, n, j, t) in parts.items()
    }


def held_out_character_glb() -> bytes:
    """The held-out character as GLB bytes (module docstring)."""
    pos, g = _world()
    arm = ARMATURE_SCALE
    world = np.array(
        [
            np.block([[rot.to_matrix(g[k]) * arm, pos[k][:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])
            for k in range(len(NAMES))
        ]
    )
    nodes = armature_nodes(world, g, NAMES, PARENTS, ARMATURE_SCALE, "body")
    data = bytearray()
    views: list[dict[str, Any]] = []
    accessors: list[dict[str, Any]] = []

    def put(
        arr: npt.NDArray[Any], kind: str, component: int, target: int | None, bounds: bool = False
    ) -> int:
        blob = np.ascontiguousarray(arr).tobytes()
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(data), "byteLength": len(blob)}
        if target is not None:
            view["target"] = target
        views.append(view)
        data.extend(blob + b"\0" * (-len(blob) % 4))
        acc: dict[str, Any] = {
            "bufferView": len(views) - 1,
            "componentType": component,
            "count": len(arr),
            "type": kind,
        }
        if bounds:
            acc["min"] = [float(x) for x in arr.min(0)]
            acc["max"] = [float(x) for x in arr.max(0)]
        accessors.append(acc)
        return len(accessors) - 1

    primitives = []
    for material, (verts, norms, joints, tris) in enumerate(_tubes().values()):
        j4 = np.zeros((len(verts), 4), np.uint16)
        j4[:, 0] = joints
        w4 = np.zeros((len(verts), 4), np.float32)
        w4[:, 0] = 1.0
        primitives.append(
            {
                "attributes": {
                    "POSITION": put(verts.astype(np.float32), "VEC3", 5126, 34962, bounds=True),
                    "NORMAL": put(norms.astype(np.float32), "VEC3", 5126, 34962),
                    "JOINTS_0": put(j4, "VEC4", 5123, 34962),
                    "WEIGHTS_0": put(w4, "VEC4", 5126, 34962),
                },
                "indices": put(tris, "SCALAR", 5123, 34963),
                "material": material,
            }
        )
    ibm = np.linalg.inv(world)
    ibm_acc = put(np.swapaxes(ibm, 1, 2).astype(np.float32).reshape(-1, 16), "MAT4", 5126, None)
    accessors[ibm_acc]["count"] = len(NAMES)
    doc = {
        "asset": {"version": "2.0", "generator": "segue browser tests (held_out_character.py)"},
        "scene": 0,
        "scenes": [{"name": "held-out", "nodes": [0, len(nodes) - 1]}],
        "nodes": nodes,
        "skins": [{"name": "rig", "joints": list(range(1, len(NAMES) + 1)), "inverseBindMatrices": ibm_acc}],
        "meshes": [{"name": "body", "primitives": primitives}],
        "materials": [
            {
                "name": "skin",
                "pbrMetallicRoughness": {
                    "baseColorFactor": [0.93, 0.72, 0.58, 1],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.7,
                },
            },
            {
                "name": "suit",
                "pbrMetallicRoughness": {
                    "baseColorFactor": [0.2, 0.45, 0.85, 1],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.6,
                },
            },
        ],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(data)}],
    }
    return glb(doc, data)
