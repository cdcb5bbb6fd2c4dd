"""Run with Blender's Python (Blender as a module: ``$SEGUE_BPY_PYTHON heldout_character.py --
BONES.json OUT.glb``; tests/blender.py): build a skinned humanoid the way an artist's file is
made, and export it to GLB with Blender's own glTF exporter.

``BONES.json`` is ``{"bones": [[name, parent, head, tail, roll_deg], ...], "radius": {name: m},
"feet": {side: [foot, toes]}, "voxel": m}`` (metres, Blender's axes: Z up, the character facing
-Y, its left at +X). The armature gets those bones (Blender's own rest orientations: each bone's
Y axis along it, its roll); the body is one mesh: an ellipsoid around every bone (``radius``: its
half-width), a box under each foot from behind the ankle to the ball and one under the toes (flat
soles on the floor, z = 0), fused by a voxel remesh and decimated, then bound with Blender's
automatic weights (bone heat; envelope weights if bone heat finds no solution). Nothing is
downloaded.
"""

import json
import math
import sys

import bpy
from mathutils import Matrix, Vector

args = sys.argv[sys.argv.index("--") + 1 :]
with open(args[0]) as f:
    spec = json.load(f)
out_path = args[1]
bones = spec["bones"]
radius = spec["radius"]
by_name = {b[0]: b for b in bones}

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene

# --- the armature -------------------------------------------------------------------------------
arm = bpy.data.armatures.new("Rig")
rig = bpy.data.objects.new("Rig", arm)
scene.collection.objects.link(rig)
bpy.context.view_layer.objects.active = rig
rig.select_set(True)
bpy.ops.object.mode_set(mode="EDIT")
made = {}
for name, parent, head, tail, roll in bones:
    eb = arm.edit_bones.new(name)
    eb.head, eb.tail, eb.roll = head, tail, math.radians(roll)
    if parent:
        eb.parent = made[parent]
        eb.use_connect = (Vector(head) - made[parent].tail).length < 1e-6
    made[name] = eb
bpy.ops.object.mode_set(mode="OBJECT")
rig.select_set(False)

# --- the body: primitives fused by a voxel remesh ----------------------------------------------
parts = []


def _ellipsoid(head: Vector, tail: Vector, r: float) -> None:
    axis = tail - head
    length = max(axis.length, 1e-4)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=1.0)
    ob = bpy.context.active_object
    z = axis.normalized()
    x = z.orthogonal().normalized()
    y = z.cross(x)
    basis = Matrix((x, y, z)).transposed().to_4x4()
    ob.matrix_world = (
        Matrix.Translation((head + tail) / 2) @ basis @ Matrix.Diagonal((r, r, length / 2 + r * 0.35, 1.0))
    )
    parts.append(ob)


def _box(lo: Vector, hi: Vector) -> None:
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    ob = bpy.context.active_object
    ob.matrix_world = Matrix.Translation((lo + hi) / 2) @ Matrix.Diagonal((*(hi - lo), 1.0))
    parts.append(ob)


for name, _parent, head, tail, _roll in bones:
    if name in radius:
        _ellipsoid(Vector(head), Vector(tail), float(radius[name]))
for _side, (foot, toes) in spec["feet"].items():
    ankle = Vector(by_name[foot][2])
    ball = Vector(by_name[toes][2])
    tip = Vector(by_name[toes][3])
    half = float(spec["foot_half_width"])
    heel_y = ankle.y + float(spec["heel_behind_ankle"])
    _box(Vector((ankle.x - half, ball.y, 0.0)), Vector((ankle.x + half, heel_y, ankle.z + 0.02)))
    toe_half = half * 0.9
    _box(Vector((ball.x - toe_half, tip.y, 0.0)), Vector((ball.x + toe_half, ball.y + 0.01, ball.z + 0.015)))

bpy.ops.object.select_all(action="DESELECT")
for ob in parts:
    ob.select_set(True)
bpy.context.view_layer.objects.active = parts[0]
bpy.ops.object.join()
body = bpy.context.active_object
body.name = "Body"
bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
remesh = body.modifiers.new("Remesh", "REMESH")
remesh.mode = "VOXEL"
remesh.voxel_size = float(spec["voxel"])
bpy.ops.object.modifier_apply(modifier=remesh.name)
decimate = body.modifiers.new("Decimate", "DECIMATE")
decimate.ratio = float(spec["decimate"])
bpy.ops.object.modifier_apply(modifier=decimate.name)
bpy.ops.object.shade_smooth()

# --- skinning: automatic weights (bone heat), envelope weights when bone heat fails ------------
bpy.ops.object.select_all(action="DESELECT")
body.select_set(True)
rig.select_set(True)
bpy.context.view_layer.objects.active = rig
bpy.ops.object.parent_set(type="ARMATURE_AUTO")
unweighted = sum(1 for v in body.data.vertices if not v.groups)
method = "automatic"
if unweighted > len(body.data.vertices) // 20:
    body.vertex_groups.clear()
    bpy.ops.object.parent_set(type="ARMATURE_ENVELOPE")
    method = "envelope"
    unweighted = sum(1 for v in body.data.vertices if not v.groups)

bpy.ops.export_scene.gltf(
    filepath=out_path, export_format="GLB", use_selection=False, export_animations=False, export_skins=True
)
print(json.dumps({"vertices": len(body.data.vertices), "weights": method, "unweighted": unweighted}))
