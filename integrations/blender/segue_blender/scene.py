"""Blender's side of the add-on: reading the scene and the rig, exporting them, keying results.

Everything here touches ``bpy`` and runs in Blender's main thread; the math and the requests are
in the plain modules (:mod:`.binding`, :mod:`.authoring`, :mod:`.roles`, :mod:`.bvh`).
"""

from __future__ import annotations

import hashlib
import os
import struct
import tempfile
from collections.abc import Mapping, Sequence
from itertools import pairwise
from typing import Any

import bpy
from mathutils import Matrix, Quaternion, Vector

from . import authoring, binding, bvh, gltf, mat4, roles
from .axes import SegueFrame, to_segue

# -- the rig --------------------------------------------------------------------------------------


def matrix_tuple(m: Matrix) -> mat4.Mat4:
    """A ``mathutils.Matrix`` (4x4) as a plain tuple, row major."""
    return tuple(float(m[r][c]) for r in range(4) for c in range(4))


def deform_bones(obj: bpy.types.Object) -> list[bpy.types.Bone]:
    """The armature's deform bones (what the rig's GLB holds), in the armature's order."""
    return [b for b in obj.data.bones if b.use_deform]


def skinned_meshes(obj: bpy.types.Object) -> list[bpy.types.Object]:
    """The mesh objects an Armature modifier binds to ``obj``."""
    return [
        o
        for o in bpy.context.scene.objects
        if o.type == "MESH" and any(m.type == "ARMATURE" and m.object == obj for m in o.modifiers)
    ]


def world_bones(obj: bpy.types.Object) -> list[roles.Bone]:
    """The deform bones' rest heads and tails in the world (metres, Z up), parents the nearest
    deform ancestors."""
    mw = obj.matrix_world
    deform = {b.name for b in deform_bones(obj)}
    out = []
    for b in deform_bones(obj):
        p = b.parent
        while p is not None and p.name not in deform:
            p = p.parent
        out.append(
            roles.Bone(b.name, p.name if p else None, tuple(mw @ b.head_local), tuple(mw @ b.tail_local))
        )
    return out


def forward_hint(obj: bpy.types.Object) -> tuple[float, float, float]:
    """The armature's local -Y (Blender's forward) in the world."""
    d = obj.matrix_world.to_3x3() @ Vector((0.0, -1.0, 0.0))
    return (d.x, d.y, d.z)


def detect_roles(obj: bpy.types.Object) -> dict[str, str]:
    """Detect the rig's roles (:func:`.roles.detect_roles`) and store them on the object."""
    found = roles.detect_roles(world_bones(obj), forward_hint(obj))
    store = obj.segue_roles
    for role in roles.ROLES:
        setattr(store, role, found.get(role, ""))
    return found


def roles_of(obj: bpy.types.Object) -> dict[str, str]:
    """The rig's roles as stored (detected first when none are)."""
    store = obj.segue_roles
    found = {r: str(getattr(store, r)) for r in roles.ROLES if getattr(store, r)}
    return found or detect_roles(obj)


def checked_roles(obj: bpy.types.Object) -> dict[str, str]:
    """The rig's roles, checked: every required one set, on deform bones; ``RoleError`` naming
    what to fix in the Rig panel."""
    found = roles_of(obj)
    missing = roles.missing_roles(found)
    if missing:
        raise roles.RoleError(f"{obj.name}: set the bones of {', '.join(missing)} in Segue's Rig panel")
    deform = {b.name for b in deform_bones(obj)}
    not_deform = [f"{r} ({b})" for r, b in found.items() if b not in deform]
    if not_deform:
        raise roles.RoleError(f"{obj.name}: roles on bones that do not deform: {', '.join(not_deform)}")
    return found


def upload_names(obj: bpy.types.Object) -> dict[str, str]:
    """Bone name -> name in the uploaded rig and clips (roles renamed)."""
    return roles.upload_names([b.name for b in obj.data.bones], checked_roles(obj))


def rest_bones(obj: bpy.types.Object) -> dict[str, binding.RestBone]:
    """Every bone's rest matrix (armature space) and parent."""
    return {
        b.name: binding.RestBone(b.name, b.parent.name if b.parent else None, matrix_tuple(b.matrix_local))
        for b in obj.data.bones
    }


def rig_fingerprint(obj: bpy.types.Object) -> str:
    """A digest of what the rig's GLB depends on: bones (names, parents, rest matrices, deform),
    the armature object's world matrix, the roles, and each bound mesh's world matrix, vertices
    and vertex groups."""
    h = hashlib.sha256()
    h.update(repr(sorted(roles_of(obj).items())).encode())
    h.update(struct.pack("<16d", *matrix_tuple(obj.matrix_world)))
    for b in obj.data.bones:
        h.update(f"{b.name}|{b.parent.name if b.parent else ''}|{int(b.use_deform)}".encode())
        h.update(struct.pack("<16d", *matrix_tuple(b.matrix_local)))
    for m in sorted(skinned_meshes(obj), key=lambda o: o.name):
        h.update(m.name.encode())
        h.update(struct.pack("<16d", *matrix_tuple(m.matrix_world)))
        co = [0.0] * (3 * len(m.data.vertices))
        m.data.vertices.foreach_get("co", co)
        h.update(struct.pack(f"<{len(co)}f", *co))
        h.update("|".join(g.name for g in m.vertex_groups).encode())
    return h.hexdigest()


class _Selection:
    """Select ``objects`` (and make the first active) for an exporter; restore afterwards."""

    def __init__(self, objects: Sequence[bpy.types.Object]) -> None:
        self.objects = objects

    def __enter__(self) -> None:
        vl = bpy.context.view_layer
        self.was_active = vl.objects.active
        self.was_selected = [o for o in bpy.context.scene.objects if o.select_get()]
        self.was_mode = bpy.context.object.mode if bpy.context.object else "OBJECT"
        if self.was_mode != "OBJECT" and bpy.context.object is not None:
            bpy.ops.object.mode_set(mode="OBJECT")
        for o in self.was_selected:
            o.select_set(False)
        for o in self.objects:
            o.select_set(True)
        vl.objects.active = self.objects[0]

    def __exit__(self, *exc: object) -> None:
        for o in self.objects:
            o.select_set(False)
        for o in self.was_selected:
            if o.name in bpy.context.scene.objects:
                o.select_set(True)
        bpy.context.view_layer.objects.active = self.was_active
        if self.was_mode != "OBJECT" and self.was_active is not None:
            bpy.ops.object.mode_set(mode=self.was_mode)


def _export_glb(objects: Sequence[bpy.types.Object], animations: bool) -> bytes:
    fd, path = tempfile.mkstemp(suffix=".glb", prefix="segue-")
    os.close(fd)
    try:
        with _Selection(objects):
            bpy.ops.export_scene.gltf(
                filepath=path,
                export_format="GLB",
                use_selection=True,
                export_yup=True,
                export_apply=False,
                export_def_bones=True,
                export_skins=True,
                export_morph=False,
                export_materials="NONE",
                export_texcoords=False,
                export_animations=animations,
                export_animation_mode="ACTIVE_ACTIONS",
                export_force_sampling=True,
                export_optimize_animation_size=False,
                export_rest_position_armature=True,
                export_anim_single_armature=True,
            )
        with open(path, "rb") as fh:
            return fh.read()
    finally:
        os.unlink(path)


def export_rig(obj: bpy.types.Object) -> bytes:
    """The character as Segue's download takes it: the armature's deform bones and the meshes it
    deforms, rest pose, no animation or material, as GLB (Blender's glTF exporter, Y up), its role
    bones renamed (:func:`upload_names`)."""
    names = upload_names(obj)
    raw = _export_glb([obj, *skinned_meshes(obj)], animations=False)
    return gltf.rename_nodes(raw, names)


def export_clip(
    obj: bpy.types.Object,
    action: bpy.types.Action,
    keep_names: bool = False,
    origin: tuple[float, float] = (0.0, 0.0),
) -> str:
    """The armature playing ``action`` as BVH text for Segue (Blender's glTF exporter samples it
    at the scene's rate; :func:`.bvh.glb_to_bvh`), role bones renamed unless ``keep_names``;
    ``origin`` (a Blender floor point) becomes the clip's origin."""
    ad = obj.animation_data or obj.animation_data_create()
    previous = ad.action
    scene = bpy.context.scene
    frame = scene.frame_current
    try:
        ad.action = action
        if getattr(ad, "action_slot", "none") is None and len(action.slots):  # Blender 4.4+: slotted
            ad.action_slot = action.slots[0]
        raw = _export_glb([obj], animations=True)
    finally:
        ad.action = previous
        scene.frame_set(frame)
    names = {b.name: b.name for b in obj.data.bones} if keep_names else upload_names(obj)
    raw = gltf.rename_nodes(raw, names)
    mw = obj.matrix_world
    tips = {names[b.name]: to_segue(tuple(mw @ b.tail_local)) for b in obj.data.bones if not b.children}
    return bvh.glb_to_bvh(raw, scene_fps(scene), tips, (origin[0], -origin[1]))


def hip_height(obj: bpy.types.Object) -> float | None:
    """The rig's hips above its ankles (their mean) at rest, in the world (metres), from its
    roles: what Segue's retargeting scales a root path by, over the database performers' own
    (their summary's ``skeleton.hip_height_m``)."""
    found = roles_of(obj)
    mw = obj.matrix_world
    try:
        hips, left, right = (obj.data.bones[found[r]] for r in ("Hips", "LeftFoot", "RightFoot"))
    except KeyError:
        return None
    up = (mw @ hips.head_local).z - 0.5 * ((mw @ left.head_local).z + (mw @ right.head_local).z)
    return up if up > 0 else None


def scene_fps(scene: bpy.types.Scene) -> float:
    return float(scene.render.fps) / float(scene.render.fps_base)


# -- the scene's authoring ------------------------------------------------------------------------


def goals_in(scene: bpy.types.Scene, dancers: Sequence[bpy.types.Object]) -> list[authoring.Goal]:
    """Every Empty with ``segue_frame`` as a goal; ``segue_dancer`` an index or an armature name."""
    out = []
    index = {o.name: i for i, o in enumerate(dancers)}
    for o in scene.objects:
        if o.type != "EMPTY" or "segue_frame" not in o:
            continue
        facing = None
        if o.get("segue_heading"):
            d = o.matrix_world.to_3x3() @ Vector((0.0, -1.0, 0.0))
            facing = (d.x, d.y)
        who = o.get("segue_dancer", 0)
        dancer = index.get(who, 0) if isinstance(who, str) else int(who)
        p = o.matrix_world.translation
        out.append(authoring.Goal(o.name, float(o["segue_frame"]), (p.x, p.y, p.z), facing, dancer))
    return out


def curve_points(obj: bpy.types.Object) -> list[tuple[float, float, float]]:
    """A curve object's first spline as world points (Bezier splines at their resolution)."""
    from mathutils.geometry import interpolate_bezier

    if obj.type != "CURVE" or not obj.data.splines:
        raise authoring.AuthoringError(f"{obj.name} is not a curve with a spline")
    spline = obj.data.splines[0]
    mw = obj.matrix_world
    pts: list[Vector] = []
    if spline.type == "BEZIER":
        bp = list(spline.bezier_points)
        segs = list(pairwise(bp))
        if spline.use_cyclic_u and bp:
            segs.append((bp[-1], bp[0]))
        res = max(2, spline.resolution_u + 1)
        for a, b in segs:
            seg = interpolate_bezier(a.co, a.handle_right, b.handle_left, b.co, res)
            pts += seg if not pts else seg[1:]
    else:
        pts = [Vector(p.co[:3]) for p in spline.points]
    return [tuple(mw @ p) for p in pts]


def sound_strip(scene: bpy.types.Scene) -> tuple[str, int] | None:
    """The file and start frame of the scene's first sound strip, if any."""
    ed = scene.sequence_editor
    if ed is None:
        return None
    strips = ed.strips_all if hasattr(ed, "strips_all") else ed.sequences_all  # renamed in Blender 5
    for s in strips:
        if s.type == "SOUND" and not s.mute and s.sound is not None:
            return bpy.path.abspath(s.sound.filepath), int(s.frame_final_start)
    return None


def scene_inputs(
    scene: bpy.types.Scene,
    dancers: Sequence[bpy.types.Object],
    path: bpy.types.Object | None,
    speed: float,
    bpm: float | None,
) -> authoring.SceneInputs:
    """What the scene authors (uploads, e.g. the sound file or the leader, are added later)."""
    timing = authoring.Timing(scene.frame_start, scene.frame_end, scene_fps(scene))
    markers = [authoring.Marker(m.name, m.frame) for m in scene.timeline_markers]
    return authoring.SceneInputs(
        timing,
        goals=goals_in(scene, dancers),
        path=curve_points(path) if path is not None else None,
        speed=speed,
        markers=markers,
        bpm=bpm,
        dancers=max(1, len(dancers)),
    )


# -- results on the rig ---------------------------------------------------------------------------


class MathutilsOps:
    """:class:`.binding.MatrixOps` on ``mathutils.Matrix`` (C speed)."""

    def matrix(self, m: mat4.Mat4) -> Matrix:
        return Matrix((m[0:4], m[4:8], m[8:12], m[12:16]))

    def trs(self, t: Sequence[float], q: Sequence[float], s: Sequence[float]) -> Matrix:
        return Matrix.LocRotScale(Vector(t), Quaternion((q[3], q[0], q[1], q[2])), Vector(s))

    def mul(self, a: Matrix, b: Matrix) -> Matrix:
        return a @ b


def _fcurves(action: bpy.types.Action, obj: bpy.types.Object) -> Any:
    """A function (data path, index, group) -> an F-curve of ``action`` for ``obj``: Blender 4.4+
    keeps F-curves in slotted layers (``Action.fcurves`` is gone in 5.0), older ones on the action."""
    if hasattr(action, "fcurve_ensure_for_datablock"):
        return lambda path, index, group: action.fcurve_ensure_for_datablock(
            obj, path, index=index, group_name=group
        )
    return lambda path, index, group: action.fcurves.new(path, index=index, action_group=group)


def _set_keys(fc: Any, frames: Sequence[float], values: Sequence[float]) -> None:
    if all(abs(v - values[0]) < 1e-7 for v in values):
        frames, values = frames[:1], values[:1]
    kp = fc.keyframe_points
    kp.add(len(frames))
    co = [0.0] * (2 * len(frames))
    co[0::2] = frames
    co[1::2] = values
    kp.foreach_set("co", co)
    kp.foreach_set("interpolation", [1] * len(frames))  # LINEAR
    fc.update()


def key_result(
    obj: bpy.types.Object,
    prepared: binding.Binding,
    start_frame: float,
    frame_step: float,
    action_name: str,
) -> tuple[bpy.types.Action, dict[str, list[Matrix]]]:
    """Key a bound result on the armature as a new action named ``action_name`` (replacing one of
    that name) and make it the armature's action; the artist's own action is kept (a fake user).

    Each of the result's bones gets location, rotation (in the bone's own rotation mode) and scale
    keys, one per result frame at ``start_frame + k * frame_step``; the bones above them that the
    rig's GLB left out (not deforming) are keyed at rest so that the poses hold. Returns the
    action and each bone's pose matrices (armature space)."""
    poses = binding.pose_matrices(prepared, MathutilsOps())
    bones = obj.data.bones
    frames_n = len(prepared.times)
    frames = [start_frame + k * frame_step for k in range(frames_n)]
    keyed = set(poses)
    for name in list(poses):
        p = bones[name].parent
        while p is not None and p.name not in keyed:
            keyed.add(p.name)
            p = p.parent
    ad = obj.animation_data or obj.animation_data_create()
    previous = ad.action
    if previous is not None and previous.name != action_name and not previous.get("segue_job"):
        previous.use_fake_user = True
    old = bpy.data.actions.get(action_name)
    if old is not None:
        if ad.action == old:
            ad.action = None
        bpy.data.actions.remove(old)
    action = bpy.data.actions.new(action_name)
    action["segue_job"] = action_name
    ad.action = action
    new_curve = _fcurves(action, obj)
    pose_of: dict[str, list[Matrix]] = {}
    ident = Matrix.Identity(4)

    def parent_pose(bone: bpy.types.Bone) -> list[Matrix] | None:
        return pose_of[bone.parent.name] if bone.parent is not None and bone.parent.name in pose_of else None

    for bone in bones:  # parents before children
        if bone.name not in keyed:
            continue
        pbone = obj.pose.bones[bone.name]
        rest = bone.matrix_local
        prest = bone.parent.matrix_local if bone.parent is not None else None
        parents = parent_pose(bone)
        if bone.name in poses:
            seq = poses[bone.name]
            basis = []
            for k, pose in enumerate(seq):
                if bone.parent is None:
                    basis.append(bone.convert_local_to_pose(pose, rest, invert=True))
                else:
                    pp = parents[k] if parents is not None else prest
                    basis.append(
                        bone.convert_local_to_pose(
                            pose, rest, parent_matrix=pp, parent_matrix_local=prest, invert=True
                        )
                    )
            pose_of[bone.name] = list(seq)
        else:
            basis = [ident] * frames_n
            if bone.parent is None:
                pose_of[bone.name] = [rest.copy()] * frames_n
            else:
                pose_of[bone.name] = [
                    bone.convert_local_to_pose(
                        ident,
                        rest,
                        parent_matrix=(parents[k] if parents else prest),
                        parent_matrix_local=prest,
                    )
                    for k in range(frames_n)
                ]
        _key_bone(new_curve, pbone, basis, frames)
    return action, {n: pose_of[n] for n in poses}


def _key_bone(
    new_curve: Any, pbone: bpy.types.PoseBone, basis: Sequence[Matrix], frames: Sequence[float]
) -> None:
    name = pbone.name
    path = f'pose.bones["{bpy.utils.escape_identifier(name)}"]'
    locs, rots, scales = [], [], []
    mode = pbone.rotation_mode
    prev_q: Quaternion | None = None
    prev_e = None
    for m in basis:
        loc, q, sc = m.decompose()
        if prev_q is not None and prev_q.dot(q) < 0:
            q.negate()
        prev_q = q
        locs.append(loc)
        scales.append(sc)
        if mode == "QUATERNION":
            rots.append(tuple(q))
        elif mode == "AXIS_ANGLE":
            axis, angle = q.to_axis_angle()
            rots.append((angle, *axis))
        else:
            e = q.to_euler(mode, prev_e) if prev_e is not None else q.to_euler(mode)
            prev_e = e
            rots.append(tuple(e))
    prop = {"QUATERNION": "rotation_quaternion", "AXIS_ANGLE": "rotation_axis_angle"}.get(
        mode, "rotation_euler"
    )
    for i in range(3):
        _set_keys(new_curve(f"{path}.location", i, name), frames, [v[i] for v in locs])
        _set_keys(new_curve(f"{path}.scale", i, name), frames, [v[i] for v in scales])
    for i in range(len(rots[0])):
        _set_keys(new_curve(f"{path}.{prop}", i, name), frames, [v[i] for v in rots])


def world_heads(
    obj: bpy.types.Object, poses: Mapping[str, Sequence[Matrix]], bone: str
) -> list[tuple[float, float, float]]:
    """A bone's head in the world at each keyed frame."""
    mw = obj.matrix_world
    return [tuple(mw @ p.translation) for p in poses.get(bone, [])]


def scale_for(obj: bpy.types.Object, summary: Mapping[str, Any]) -> float:
    """The rig's size over the database performers' (hip heights), 1 when either is unknown."""
    own = hip_height(obj)
    ref = (summary.get("skeleton") or {}).get("hip_height_m")
    if not own or not ref:
        return 1.0
    return float(own) / float(ref)


def anchor_of(inputs: authoring.SceneInputs, obj: bpy.types.Object) -> tuple[float, float]:
    """Where Segue's origin goes: the first goal, else the path's start, else the character's hips."""
    if inputs.goals:
        g = min(inputs.goals, key=lambda g: g.frame)
        return (g.position[0], g.position[1])
    if inputs.path:
        return (inputs.path[0][0], inputs.path[0][1])
    found = roles_of(obj)
    hips = obj.data.bones.get(found.get("Hips", "")) if found.get("Hips") else None
    if hips is not None:
        p = obj.matrix_world @ hips.head_local
        return (p.x, p.y)
    p = obj.matrix_world.translation
    return (p.x, p.y)


def frame_of(inputs: authoring.SceneInputs, obj: bpy.types.Object, summary: Mapping[str, Any]) -> SegueFrame:
    return SegueFrame(anchor_of(inputs, obj), scale_for(obj, summary))
