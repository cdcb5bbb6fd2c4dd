# Run inside Godot 3.2 (godot3 --path PROJECT -s godot_check.gd), after the editor imported the
# project's GLBs: for each res://*.glb, what came in, as one JSON line per file on stdout
# ("GODOT_CHECK {...}"), read by tests/motion/test_engine_roundtrip.py.
#
# Per file: the Skeletons (bone -> parent), the MeshInstances and the Skeleton each is bound to,
# the animations with their tracks (each track's node and bone resolved, or not), the bone world
# positions (glTF axes: Godot's are the same) at the times listed in res://times.txt, and for each
# animation the documented root-motion recipe run frame by frame (60 steps a second) with the
# track named in res://root_track.txt: where the body ends.
extends SceneTree


func _find(node, kind, out):
	if node.is_class(kind):
		out.append(node)
	for c in node.get_children():
		_find(c, kind, out)


func _init():
	var times = []
	var f = File.new()
	f.open("res://times.txt", File.READ)
	for t in f.get_as_text().split(","):
		times.append(float(t))
	f.close()
	f.open("res://root_track.txt", File.READ)
	var root_track = f.get_as_text().strip_edges()
	f.close()
	var dir = Directory.new()
	dir.open("res://")
	dir.list_dir_begin(true)
	var name = dir.get_next()
	while name != "":
		if name.ends_with(".glb"):
			print("GODOT_CHECK " + to_json(_check("res://" + name, times, root_track)))
		name = dir.get_next()
	quit()


# The events, as docs/game-engines.md reads them in Godot 3.2 (its importer drops glTF extras):
# from the GLB's JSON chunk.
func read_events(path):
	var f = File.new()
	f.open(path, File.READ)
	f.seek(12)
	var n = f.get_32()
	f.seek(20)
	var gltf = JSON.parse(f.get_buffer(n).get_string_from_utf8()).result
	f.close()
	var scene = gltf["scenes"][gltf.get("scene", 0)]
	return scene.get("extras", {}).get("events", [])


func _check(path, times, root_track):
	var scene = load(path).instance()
	get_root().add_child(scene)
	var out = {"file": path.get_file(), "skeletons": [], "meshes": [], "animations": [],
		"events": read_events(path)}
	var skels = []
	_find(scene, "Skeleton", skels)
	for s in skels:
		var bones = {}
		for i in range(s.get_bone_count()):
			var p = s.get_bone_parent(i)
			bones[s.get_bone_name(i)] = null if p < 0 else s.get_bone_name(p)
		out["skeletons"].append({"path": str(scene.get_path_to(s)), "bones": bones})
	var meshes = []
	_find(scene, "MeshInstance", meshes)
	for m in meshes:
		var binds = []
		if m.skin != null:
			for i in range(m.skin.get_bind_count()):
				var o = m.skin.get_bind_pose(i).origin
				binds.append([o.x, o.y, o.z])
		var skel = m.get_node_or_null(m.skeleton)
		out["meshes"].append({"name": m.name, "skeleton": str(m.skeleton), "skin": m.skin != null,
			"skin_ref": str(m.skin), "binds": binds,
			"skeleton_path": str(scene.get_path_to(skel)) if skel != null else ""})
	var players = []
	_find(scene, "AnimationPlayer", players)
	if players.empty():
		return out
	var player = players[0]
	var base = player.get_node(player.root_node)
	for anim_name in player.get_animation_list():
		var anim = player.get_animation(anim_name)
		var tracks = []
		for i in range(anim.get_track_count()):
			var tp = anim.track_get_path(i)
			var node = base.get_node_or_null(NodePath(str(tp).split(":")[0]))
			var bone = tp.get_subname(0) if tp.get_subname_count() > 0 else ""
			var ok = node != null and node.is_class("Skeleton") and node.find_bone(bone) >= 0
			tracks.append({"path": str(tp), "bound": ok})
		var poses = []
		player.play(anim_name)
		for t in times:
			player.seek(t, true)
			var frame = {}
			for s in skels:
				for i in range(s.get_bone_count()):
					var w = s.global_transform * s.get_bone_global_pose(i)
					frame[s.get_bone_name(i)] = [w.origin.x, w.origin.y, w.origin.z]
			poses.append(frame)
		player.stop()
		out["animations"].append({"name": anim_name, "length": anim.length, "tracks": tracks,
			"poses": poses, "root_motion": _root_motion(player, anim_name, anim.length, skels, root_track),
			"hips_motion": _hips_motion(player, anim_name, skels, times)})
	return out


# The documented recipe (docs/game-engines.md, Godot 3.2): the AnimationTree's root-motion step
# is already in the skeleton's space: add it as it is, and turn the body by its rotation.
func _root_motion(player, anim_name, length, skels, root_track):
	if skels.empty():
		return null
	var skel = skels[0]
	var tree = AnimationTree.new()
	player.get_parent().add_child(tree)
	var node = AnimationNodeAnimation.new()
	node.animation = anim_name
	tree.tree_root = node
	tree.anim_player = tree.get_path_to(player)
	var base = player.get_node(player.root_node)
	var bone = root_track if skel.find_bone(root_track) >= 0 else skel.get_bone_name(0)  # no root: hips
	tree.root_motion_track = NodePath(str(base.get_path_to(skel)) + ":" + bone)
	tree.process_mode = AnimationTree.ANIMATION_PROCESS_MANUAL
	tree.active = true
	# the skeleton's transform in the scene (an Armature's 0.01 scale): the step is in its space
	var to_scene = player.get_parent().global_transform.affine_inverse() * skel.global_transform
	var body = Transform()
	var turned = Transform()  # the recipe the docs gave before (each step turned again): for the record
	var steps = int(round(length * 60.0))
	tree.advance(0.0)
	for i in range(steps):
		tree.advance(length / steps)
		var step = tree.get_root_motion_transform()
		body.origin += to_scene.basis.xform(step.origin)
		body.basis = body.basis * step.basis
		turned.origin += turned.basis.xform(to_scene.basis.xform(step.origin))
		turned.basis = turned.basis * step.basis
	tree.queue_free()
	var fwd = body.basis.z
	return {"end": [body.origin.x, body.origin.y, body.origin.z], "forward": [fwd.x, fwd.y, fwd.z],
		"end_turned_each_step": [turned.origin.x, turned.origin.y, turned.origin.z]}


# The documented recipe for a rig without a root bone (docs/game-engines.md, Godot 3.2): root
# motion on the hips, taken from their own track while the AnimationPlayer plays everything; the
# body walks the hips' floor path and the character's node steps back by as much, so the mesh
# stays over the body. Where the body ends, and the hips' world position at the listed times.
func _hips_motion(player, anim_name, skels, times):
	if skels.empty():
		return null
	var skel = skels[0]
	var hips = 0
	for i in range(skel.get_bone_count()):
		if skel.get_bone_parent(i) < 0:
			hips = i
			break
	var anim = player.get_animation(anim_name)
	var base = player.get_node(player.root_node)
	var track = anim.find_track(NodePath(str(base.get_path_to(skel)) + ":" + skel.get_bone_name(hips)))
	if track < 0:
		return null
	var visual = player.get_parent()
	var body = Spatial.new()
	visual.get_parent().add_child(body)
	visual.get_parent().remove_child(visual)
	body.add_child(visual)
	var to_visual = visual.global_transform.affine_inverse() * skel.global_transform
	var rest = skel.get_bone_rest(hips)
	var start = _hips_floor(anim, track, 0.0, rest, to_visual)
	var last = start
	player.play(anim_name)
	var steps = int(round(anim.length * 60.0))
	var seen = []
	for i in range(steps + 1):
		var time = anim.length * i / steps
		player.seek(time, true)
		var now = _hips_floor(anim, track, time, rest, to_visual)
		body.translation += body.transform.basis.xform(now - last)   # move_and_slide(... / delta)
		last = now
		visual.translation = -(now - start)                            # the mesh stays over the body
		for t in times:
			if abs(time - t) < 0.5 * anim.length / steps:
				var w = skel.global_transform * skel.get_bone_global_pose(hips)
				seen.append([w.origin.x, w.origin.y, w.origin.z])
	player.stop()
	return {"end": [body.translation.x, body.translation.y, body.translation.z], "hips": seen}


# the hips' floor position in the character's node (its y dropped), from their track at a time
func _hips_floor(anim, track, time, rest, to_visual):
	var at = to_visual.xform(rest.xform(anim.transform_track_interpolate(track, time)[0]))
	return Vector3(at.x, 0.0, at.z)
