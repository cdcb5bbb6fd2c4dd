"""Skinned test characters built inside Blender with bpy, as artists' rigs are: an armature with
its own bone names (no naming convention Segue knows), bones with Blender's own rest orientations
(each bone's Y axis along it, rolls of its own), a body mesh bound with an Armature modifier and
vertex-group weights that blend across joints.

* ``courier``: Rigify-style deform bones (``DEF-thigh.L``, split ``.001`` segments), a game
  rig's deforming ``root`` bone on the floor (no vertices), the armature object turned 90 degrees
  about Z and moved off the origin.
* ``ferry``: an FBX import from a Y-up program: the armature object rotated +90 degrees about X
  and scaled 0.01, its bones in centimetres along Y up, names with no side token at all
  (``leg_a`` / ``leg_b``), no bone above the pelvis.

Run inside Blender (``import rigs`` with this folder on ``sys.path``). Nothing is downloaded.
"""

from __future__ import annotations

import math

import bpy
from mathutils import Euler, Matrix, Vector

# name, parent, head, tail, roll (degrees); metres, Z up, the character facing -Y (left = +X)
_COURIER = [
    ("root", None, (0, 0, 0), (0, 0.3, 0), 0),
    ("DEF-spine", "root", (0, 0.02, 0.97), (0, 0.03, 1.09), 0),
    ("DEF-spine.001", "DEF-spine", (0, 0.03, 1.09), (0, 0.02, 1.23), 0),
    ("DEF-spine.002", "DEF-spine.001", (0, 0.02, 1.23), (0, 0.03, 1.40), 0),
    ("DEF-spine.004", "DEF-spine.002", (0, 0.03, 1.43), (0, 0.01, 1.53), 0),
    ("DEF-spine.006", "DEF-spine.004", (0, 0.01, 1.53), (0, 0.0, 1.74), 0),
]
for side, sx in (("L", 1.0), ("R", -1.0)):
    _COURIER += [
        (f"DEF-thigh.{side}", "DEF-spine", (0.095 * sx, 0.0, 0.95), (0.10 * sx, -0.01, 0.73), 4 * sx),
        (
            f"DEF-thigh.{side}.001",
            f"DEF-thigh.{side}",
            (0.10 * sx, -0.01, 0.73),
            (0.105 * sx, -0.02, 0.51),
            4 * sx,
        ),
        (
            f"DEF-shin.{side}",
            f"DEF-thigh.{side}.001",
            (0.105 * sx, -0.02, 0.51),
            (0.105 * sx, 0.0, 0.30),
            -3 * sx,
        ),
        (
            f"DEF-shin.{side}.001",
            f"DEF-shin.{side}",
            (0.105 * sx, 0.0, 0.30),
            (0.105 * sx, 0.03, 0.085),
            -3 * sx,
        ),
        (f"DEF-foot.{side}", f"DEF-shin.{side}.001", (0.105 * sx, 0.03, 0.085), (0.11 * sx, -0.10, 0.02), 0),
        (f"DEF-toe.{side}", f"DEF-foot.{side}", (0.11 * sx, -0.10, 0.02), (0.11 * sx, -0.17, 0.02), 0),
        (f"DEF-shoulder.{side}", "DEF-spine.002", (0.02 * sx, -0.01, 1.39), (0.16 * sx, 0.03, 1.41), 10 * sx),
        (
            f"DEF-upper_arm.{side}",
            f"DEF-shoulder.{side}",
            (0.18 * sx, 0.03, 1.40),
            (0.30 * sx, 0.04, 1.27),
            30 * sx,
        ),
        (
            f"DEF-upper_arm.{side}.001",
            f"DEF-upper_arm.{side}",
            (0.30 * sx, 0.04, 1.27),
            (0.41 * sx, 0.05, 1.14),
            30 * sx,
        ),
        (
            f"DEF-forearm.{side}",
            f"DEF-upper_arm.{side}.001",
            (0.41 * sx, 0.05, 1.14),
            (0.49 * sx, 0.02, 1.03),
            80 * sx,
        ),
        (
            f"DEF-forearm.{side}.001",
            f"DEF-forearm.{side}",
            (0.49 * sx, 0.02, 1.03),
            (0.56 * sx, -0.01, 0.93),
            80 * sx,
        ),
        (
            f"DEF-hand.{side}",
            f"DEF-forearm.{side}.001",
            (0.56 * sx, -0.01, 0.93),
            (0.59 * sx, -0.02, 0.86),
            80 * sx,
        ),
        (
            f"DEF-f_index.01.{side}",
            f"DEF-hand.{side}",
            (0.59 * sx, -0.03, 0.86),
            (0.60 * sx, -0.04, 0.82),
            80 * sx,
        ),
        (
            f"DEF-thumb.01.{side}",
            f"DEF-hand.{side}",
            (0.57 * sx, -0.04, 0.90),
            (0.58 * sx, -0.07, 0.87),
            20 * sx,
        ),
    ]

# Y up, centimetres, facing +Z (a Y-up program's convention); leg_a is the character's left (+X)
_FERRY = [
    ("Pelvis", None, (0, 103, 0), (0, 116, -1), 0),
    ("Spine_lo", "Pelvis", (0, 116, -1), (0, 133, -2), 0),
    ("Spine_hi", "Spine_lo", (0, 133, -2), (0, 152, 0), 0),
    ("Neck", "Spine_hi", (0, 155, 0), (0, 165, 1), 0),
    ("Skull", "Neck", (0, 165, 1), (0, 188, 0), 0),
]
for part, sx in (("a", 1.0), ("b", -1.0)):
    _FERRY += [
        (f"leg_{part}", "Pelvis", (10 * sx, 100, 0), (11 * sx, 55, 1.5), 0),
        (f"knee_{part}", f"leg_{part}", (11 * sx, 55, 1.5), (11 * sx, 9.5, -3), 0),
        (f"ankle_{part}", f"knee_{part}", (11 * sx, 9.5, -3), (11.5 * sx, 2.5, 11), 0),
        (f"ball_{part}", f"ankle_{part}", (11.5 * sx, 2.5, 11), (11.5 * sx, 2.5, 18), 0),
        (f"collar_{part}", "Spine_hi", (3 * sx, 149, 1), (17 * sx, 151, -2), 0),
        (f"arm_{part}", f"collar_{part}", (19 * sx, 150, -2), (47 * sx, 149, -3), 0),
        (f"elbow_{part}", f"arm_{part}", (47 * sx, 149, -3), (73 * sx, 149, 0), 0),
        (f"wrist_{part}", f"elbow_{part}", (73 * sx, 149, 0), (82 * sx, 148, 1), 0),
    ]


def _segments(bones: list[tuple]) -> list[tuple[str, Vector, Vector]]:
    return [(name, Vector(head), Vector(tail)) for name, _p, head, tail, _r in bones]


def _body_mesh(name: str, bones: list[tuple], radius: dict[str, float], skip: set[str]) -> bpy.types.Object:
    """A low-poly body: a ring of 8 vertices every few centimetres along each bone, each vertex
    weighted to its bone and, near the bone's ends, blended with the parent or the child."""
    verts: list[Vector] = []
    faces: list[tuple[int, ...]] = []
    weights: list[dict[str, float]] = []
    children = {}
    for bname, parent, *_ in bones:
        if parent:
            children.setdefault(parent, []).append(bname)
    by_name = {b[0]: b for b in bones}
    for bname, parent, head, tail, _roll in bones:
        if bname in skip:
            continue
        h, t = Vector(head), Vector(tail)
        axis = t - h
        length = axis.length
        r = radius.get(bname, 0.04) * length if length > 1 else radius.get(bname, 0.04)
        z = axis.normalized()
        x = z.orthogonal().normalized()
        y = z.cross(x)
        rings = max(2, int(length / (0.06 if length < 2 else 6)) + 1)
        base = len(verts)
        for k in range(rings):
            u = k / (rings - 1)
            c = h + axis * u
            for m in range(8):
                a = 2 * math.pi * m / 8
                verts.append(c + (x * math.cos(a) + y * math.sin(a)) * r)
                w = {bname: 1.0}
                kids = [c2 for c2 in children.get(bname, []) if c2 not in skip]
                if u < 0.2 and parent and parent in by_name and parent not in skip:
                    w = {bname: 0.5 + 2.5 * u, parent: 0.5 - 2.5 * u}
                elif u > 0.8 and len(kids) == 1:
                    w = {bname: 0.5 + 2.5 * (1 - u), kids[0]: 0.5 - 2.5 * (1 - u)}
                weights.append(w)
        for k in range(rings - 1):
            for m in range(8):
                a0 = base + k * 8 + m
                a1 = base + k * 8 + (m + 1) % 8
                faces.append((a0, a1, a1 + 8, a0 + 8))
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in verts], [], faces)
    me.update()
    ob = bpy.data.objects.new(name, me)
    for i, w in enumerate(weights):
        for g, value in w.items():
            vg = ob.vertex_groups.get(g) or ob.vertex_groups.new(name=g)
            vg.add([i], value, "REPLACE")
    return ob


def _build(
    name: str, bones: list[tuple], matrix: Matrix, radius: dict[str, float], skip: set[str], no_mesh: set[str]
) -> bpy.types.Object:
    arm = bpy.data.armatures.new(name)
    ob = bpy.data.objects.new(name, arm)
    bpy.context.scene.collection.objects.link(ob)
    ob.matrix_world = matrix
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")
    made = {}
    for bname, parent, head, tail, roll in bones:
        eb = arm.edit_bones.new(bname)
        eb.head, eb.tail, eb.roll = head, tail, math.radians(roll)
        if parent:
            eb.parent = made[parent]
            eb.use_connect = (Vector(head) - made[parent].tail).length < 1e-6 and not bname.endswith(
                "thumb.01.L"
            )
        made[bname] = eb
    bpy.ops.object.mode_set(mode="OBJECT")
    for bname in skip:
        arm.bones[bname].use_deform = False
    body = _body_mesh(f"{name}_body", bones, radius, skip | no_mesh)
    bpy.context.scene.collection.objects.link(body)
    body.parent = ob
    mod = body.modifiers.new("Armature", "ARMATURE")
    mod.object = ob
    ob.select_set(False)
    return ob


def courier(
    location: tuple[float, float, float] = (0.6, -0.4, 0.0), turn_deg: float = 90.0, name: str = "Courier"
) -> bpy.types.Object:
    """The Rigify-style character (module docstring), its object turned ``turn_deg`` about Z."""
    radius = {n: 0.05 for n, *_ in _COURIER}
    radius.update({"DEF-spine": 0.13, "DEF-spine.001": 0.12, "DEF-spine.002": 0.14, "DEF-spine.006": 0.09})
    matrix = Matrix.Translation(location) @ Euler((0, 0, math.radians(turn_deg))).to_matrix().to_4x4()
    return _build(name, _COURIER, matrix, radius, skip=set(), no_mesh={"root"})


def ferry(location: tuple[float, float, float] = (-0.8, 0.5, 0.0), name: str = "Ferry") -> bpy.types.Object:
    """The FBX-style character (module docstring): object rotation +90 degrees about X, scale 0.01."""
    radius = {n: 0.1 for n, *_ in _FERRY}
    radius.update({"Pelvis": 0.9, "Spine_lo": 0.7, "Spine_hi": 0.8, "Skull": 0.4})
    matrix = (
        Matrix.Translation(location)
        @ Euler((math.radians(90), 0, 0)).to_matrix().to_4x4()
        @ Matrix.Scale(0.01, 4)
    )
    return _build(name, _FERRY, matrix, radius, skip=set(), no_mesh=set())
