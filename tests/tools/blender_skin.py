"""Run with Blender's Python (Blender as a module: ``$SEGUE_BPY_PYTHON blender_skin.py -- IN.glb
OUT.json TIMES``; tests/blender.py): import a GLB with Blender's own glTF importer into an empty
scene, play its active action and write, for each skinned mesh object, its vertices as Blender
deforms them (the evaluated mesh, world space, glTF axes: Y up, metres) at each time (seconds,
comma separated), and the name of the action playing.
"""

import json
import sys

import bpy

args = sys.argv[sys.argv.index("--") + 1 :]
src, out_path, times = args[0], args[1], [float(t) for t in args[2].split(",")]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)
scene = bpy.context.scene
fps = scene.render.fps / scene.render.fps_base
arms = [o for o in scene.objects if o.type == "ARMATURE"]
report = {
    "fps": fps,
    "active": [
        o.animation_data.action.name if o.animation_data and o.animation_data.action else None for o in arms
    ],
    "meshes": [],
}
meshes = [o for o in scene.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers)]
frames = {ob.name: [] for ob in meshes}
for t in times:
    frame = t * fps
    scene.frame_set(int(frame), subframe=frame - int(frame))
    graph = bpy.context.evaluated_depsgraph_get()
    for ob in meshes:
        ev = ob.evaluated_get(graph)
        me = ev.to_mesh()
        frames[ob.name].append([[p[0], p[2], -p[1]] for p in (ob.matrix_world @ v.co for v in me.vertices)])
        ev.to_mesh_clear()
for ob in meshes:
    report["meshes"].append({"name": ob.name, "frames": frames[ob.name]})
with open(out_path, "w") as f:
    json.dump(report, f)
