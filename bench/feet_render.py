"""Pictures of a character's feet at one moment, rendered by Blender (run with Blender's Python:
``$SEGUE_BPY_PYTHON bench/feet_render.py -- FILE.glb TIME_S OUT.png [LABEL]``; tests/blender.py
makes such a Python).

The GLB is imported with Blender's glTF importer and its active action played at ``TIME_S``
seconds. A floor at the rest floor (height 0, a checker of 10 cm squares, half transparent, so
that what sinks shows through it, dimmed) is added, and Cycles renders on the CPU, 640 x 400, the
deformed mesh seen from the side, 1.1 m away and 22 cm above the floor, aimed at the mesh's
lowest vertex (the foot that touches or sinks). ``LABEL`` and the lowest vertex's height are
written in the picture's corner.
"""

import sys

import bpy
from mathutils import Vector

args = sys.argv[sys.argv.index("--") + 1 :]
src, time_s, out = args[0], float(args[1]), args[2]
label = args[3] if len(args) > 3 else ""
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)
scene = bpy.context.scene
arms = [o for o in scene.objects if o.type == "ARMATURE"]
fps = scene.render.fps / scene.render.fps_base
at = time_s * fps
scene.frame_set(int(at), subframe=at - int(at))
graph = bpy.context.evaluated_depsgraph_get()
meshes = [o for o in scene.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers)]
lowest = None
for ob in meshes:
    ev = ob.evaluated_get(graph)
    me = ev.to_mesh()
    for v in me.vertices:
        w = ob.matrix_world @ v.co
        if lowest is None or w.z < lowest.z:
            lowest = w.copy()
    ev.to_mesh_clear()
if lowest is None:
    raise SystemExit("no mesh")

# the floor: a checker plane at z = 0 (glTF's y = 0)
bpy.ops.mesh.primitive_plane_add(size=4.0, location=(lowest.x, lowest.y, 0.0))
floor = bpy.context.active_object
mat = bpy.data.materials.new("floor")
mat.use_nodes = True
nodes = mat.node_tree.nodes
checker = nodes.new("ShaderNodeTexChecker")
checker.inputs["Scale"].default_value = 40.0  # 4 m / 40 = 10 cm squares
checker.inputs["Color1"].default_value = (0.55, 0.6, 0.65, 1.0)
checker.inputs["Color2"].default_value = (0.35, 0.4, 0.45, 1.0)
mat.node_tree.links.new(checker.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
nodes["Principled BSDF"].inputs["Alpha"].default_value = 0.55  # what sinks shows through, dimmed
floor.data.materials.append(mat)

# camera: from the character's side at 12 cm above the floor, looking at the lowest vertex
cam_data = bpy.data.cameras.new("cam")
cam_data.lens = 50
cam = bpy.data.objects.new("cam", cam_data)
scene.collection.objects.link(cam)
side = Vector((1.0, 0.0, 0.0))
if arms:  # the side of the body the foot is on, seen from outside
    centre = arms[0].matrix_world @ arms[0].pose.bones[0].head
    d = lowest - centre
    d.z = 0.0
    if d.length > 1e-6:
        side = d.normalized()
cam.location = lowest * Vector((1.0, 1.0, 0.0)) + side * 1.1 + Vector((0.0, 0.0, 0.22))
direction = (lowest * Vector((1.0, 1.0, 0.0)) + Vector((0.0, 0.0, 0.08))) - cam.location
cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
scene.camera = cam
sun = bpy.data.lights.new("sun", "SUN")
sun.energy = 3.0
sun_ob = bpy.data.objects.new("sun", sun)
sun_ob.rotation_euler = (0.7, 0.2, 0.8)
scene.collection.objects.link(sun_ob)
world = bpy.data.worlds.new("world")
world.color = (0.8, 0.8, 0.8)
scene.world = world
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 16
scene.render.resolution_x, scene.render.resolution_y = 640, 400
scene.render.film_transparent = False
if label:
    scene.render.use_stamp = True
    scene.render.use_stamp_note = True
    scene.render.stamp_note_text = f"{label}  {time_s:.3f} s  lowest vertex {lowest.z * 100:+.1f} cm"
    for attr in ("use_stamp_date", "use_stamp_time", "use_stamp_render_time", "use_stamp_frame",
                 "use_stamp_scene", "use_stamp_camera", "use_stamp_filename", "use_stamp_memory",
                 "use_stamp_frame_range", "use_stamp_lens", "use_stamp_marker", "use_stamp_sequencer_strip",
                 "use_stamp_hostname"):  # fmt: skip
        if hasattr(scene.render, attr):
            setattr(scene.render, attr, False)
scene.render.filepath = out
bpy.ops.render.render(write_still=True)
print(f"FEET_RENDER {out} lowest {lowest.z:.4f}")
