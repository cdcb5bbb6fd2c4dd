"""Run with Blender's Python (Blender as a module: ``$SEGUE_BPY_PYTHON blender_check.py -- IN.glb
OUT.json TIMES``; tests/blender.py): import a GLB with Blender's own glTF importer into an empty
scene and write what came in as JSON.

For each armature: its bones (name -> parent), its actions (the active one and those stashed in
NLA tracks) with the bones their channels drive, and, for each action at each time (seconds, comma
separated), the world position of every bone's head in glTF axes (Y up, metres); for each mesh
object, how far its evaluated (deformed) vertices move from the rest pose at each time and their
lowest height; and the scene's and the armatures' custom properties named ``events``.
"""

import json
import sys

import bpy
import numpy

args = sys.argv[sys.argv.index("--") + 1 :]
src, out_path, times = args[0], args[1], [float(t) for t in args[2].split(",")]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)
scene = bpy.context.scene
fps = scene.render.fps / scene.render.fps_base


def gltf_axes(v):
    return [v[0], v[2], -v[1]]  # Blender Z up -> glTF Y up


def set_time(t):
    frame = t * fps
    scene.frame_set(int(frame), subframe=frame - int(frame))


def fcurves_of(action):
    """An action's F-curves: Blender 4.4+ keeps them in layers/strips/channel bags (slotted
    actions; ``Action.fcurves`` is gone in 5.0), older versions on the action itself."""
    if hasattr(action, "layers"):
        bags = [bag for layer in action.layers for strip in layer.strips for bag in strip.channelbags]
        return [fc for bag in bags for fc in bag.fcurves]
    return list(action.fcurves)


def events_of(idblock):
    ev = idblock.get("events")
    return None if ev is None else len(ev)


report = {"fps": fps, "armatures": [], "meshes": [], "scene_events": events_of(scene)}
arms = [o for o in scene.objects if o.type == "ARMATURE"]
for arm in arms:
    bones = {b.name: (b.parent.name if b.parent else None) for b in arm.data.bones}
    actions = []
    ad = arm.animation_data
    if ad is not None:
        if ad.action is not None:
            actions.append(ad.action)
        for track in ad.nla_tracks:
            actions += [s.action for s in track.strips if s.action is not None]
    info = {"name": arm.name, "bones": bones, "events": events_of(arm), "actions": []}
    for act in dict.fromkeys(actions):
        driven = sorted({fc.data_path.split('"')[1] for fc in fcurves_of(act) if '"' in fc.data_path})
        for track in ad.nla_tracks:  # play this action alone
            track.mute = True
        ad.action = act
        heads = []
        for t in times:
            set_time(t)
            heads.append({b.name: gltf_axes(arm.matrix_world @ b.head) for b in arm.pose.bones})
        info["actions"].append({"name": act.name, "driven": driven, "heads": heads})
    report["armatures"].append(info)
for ob in scene.objects:
    if ob.type != "MESH" or not any(m.type == "ARMATURE" for m in ob.modifiers):
        continue
    dg = bpy.context.evaluated_depsgraph_get()
    set_time(times[0])
    rest = numpy.array([ob.matrix_world @ v.co for v in ob.data.vertices])
    moved, lowest = [], []
    for t in times:
        set_time(t)
        ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
        me = ev.to_mesh()
        pts = numpy.array([ob.matrix_world @ v.co for v in me.vertices])
        ev.to_mesh_clear()
        moved.append(float(numpy.abs(pts - rest).max()))
        lowest.append(float(pts[:, 2].min()))
    report["meshes"].append(
        {
            "name": ob.name,
            "vertices": len(rest),
            "moved": moved,
            "lowest": lowest,
            "armature": next((m.object.name for m in ob.modifiers if m.type == "ARMATURE"), None),
        }
    )
with open(out_path, "w") as f:
    json.dump(report, f)
