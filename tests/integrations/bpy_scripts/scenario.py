"""Run with Blender's Python (``$SEGUE_BPY_PYTHON scenario.py -- CONFIG.json OUT.json``;
tests/blender.py): install the add-on zip ``segue blender-addon`` wrote, build the test characters
(rigs.py), run one scenario of the add-on against a running ``segue serve`` and write what came
out as JSON for the test to check (tests/integrations/test_blender_addon.py).

CONFIG holds ``zip``, ``install`` (``extension`` or ``legacy``), ``url``, ``scenario`` and the
scenario's own keys (database ids, files). Positions in OUT are Blender world metres (Z up)."""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import bpy

sys.path.insert(0, str(Path(__file__).resolve().parent))
import rigs

ARGS = sys.argv[sys.argv.index("--") + 1 :]
CFG = json.loads(Path(ARGS[0]).read_text())
OUT = Path(ARGS[1])


def addon_module(name: str):  # type: ignore[no-untyped-def]
    """A module of the installed add-on (``bl_ext.user_default.segue_blender.X`` or ``segue_blender.X``)."""
    return next(m for k, m in sys.modules.items() if k.endswith(f"segue_blender.{name}"))


def install(zip_path: str, how: str) -> str:
    if how == "extension":
        assert bpy.ops.extensions.package_install_files(
            filepath=zip_path, repo="user_default", enable_on_install=True
        ) == {"FINISHED"}
    else:
        assert bpy.ops.preferences.addon_install(filepath=zip_path) == {"FINISHED"}
        assert bpy.ops.preferences.addon_enable(module="segue_blender") == {"FINISHED"}
    return next(k for k in bpy.context.preferences.addons if k.endswith("segue_blender"))


def goal(
    name: str,
    frame: int,
    location: tuple[float, float, float],
    facing_deg: float | None = None,
    dancer: int = 0,
) -> bpy.types.Object:
    """A goal empty as an artist adds one (Empty, custom property ``segue_frame``); with
    ``facing_deg`` it also asks for the facing: the empty turned about Z (its -Y is its facing)."""
    e = bpy.data.objects.new(name, None)
    e.empty_display_type = "ARROWS"
    e.location = location
    e["segue_frame"] = frame
    if facing_deg is not None:
        e.rotation_euler = (0.0, 0.0, math.radians(facing_deg))
        e["segue_heading"] = True
    if dancer:
        e["segue_dancer"] = dancer
    bpy.context.scene.collection.objects.link(e)
    return e


def rig_state(obj: bpy.types.Object) -> dict:
    """Bones (names, parents, rest matrices, deform) and bound meshes (vertices, groups, modifiers)."""
    bones = {
        b.name: [
            b.parent.name if b.parent else None,
            [round(v, 7) for row in b.matrix_local for v in row],
            b.use_deform,
        ]
        for b in obj.data.bones
    }
    meshes = {}
    for m in bpy.context.scene.objects:
        if m.type == "MESH" and any(md.type == "ARMATURE" and md.object == obj for md in m.modifiers):
            meshes[m.name] = {
                "vertices": [round(c, 7) for v in m.data.vertices for c in v.co],
                "groups": [g.name for g in m.vertex_groups],
                "modifiers": [
                    (md.type, md.object.name if getattr(md, "object", None) else None) for md in m.modifiers
                ],
            }
    return {
        "bones": bones,
        "meshes": meshes,
        "matrix_world": [round(v, 7) for row in obj.matrix_world for v in row],
    }


def fcurves_of(action: bpy.types.Action) -> list:
    if hasattr(action, "layers"):
        return [
            fc
            for layer in action.layers
            for strip in layer.strips
            for bag in strip.channelbags
            for fc in bag.fcurves
        ]
    return list(action.fcurves)


def heads_at(obj: bpy.types.Object, frames: list[int]) -> list[dict[str, list[float]]]:
    """Every bone's head in the world at each frame, as Blender evaluates the action."""
    out = []
    sc = bpy.context.scene
    for f in frames:
        sc.frame_set(f)
        out.append({b.name: list(obj.matrix_world @ b.head) for b in obj.pose.bones})
    return out


def mesh_motion(obj: bpy.types.Object, frame: int) -> float:
    """How far the bound mesh's evaluated (deformed) vertices are from their rest at ``frame``."""
    sc = bpy.context.scene
    mesh = next(m for m in sc.objects if m.type == "MESH" and m.parent == obj)
    sc.frame_set(frame)
    ev = mesh.evaluated_get(bpy.context.evaluated_depsgraph_get())
    me = ev.to_mesh()
    moved = max(
        (mesh.matrix_world @ a.co - mesh.matrix_world @ b.co).length
        for a, b in zip(me.vertices, mesh.data.vertices, strict=True)
    )
    ev.to_mesh_clear()
    return moved


def action_report(obj: bpy.types.Object) -> dict:
    act = obj.animation_data.action if obj.animation_data else None
    if act is None:
        return {"name": None, "driven": []}
    driven = sorted(
        {fc.data_path.split('"')[1] for fc in fcurves_of(act) if fc.data_path.startswith("pose.bones")}
    )
    return {"name": act.name, "driven": driven, "frame_range": list(act.frame_range)}


def job_report() -> dict:
    state = addon_module("state")
    view = state.SESSION.job
    ops = addon_module("ops")
    return {
        "state": view.state,
        "id": view.id,
        "shown": view.shown,
        "solutions": view.solutions,
        "first_solution_s": view.first_solution_s,
        "timings": view.timings,
        "ok": view.ok,
        "reasons": view.reasons,
        "message": view.message,
        "goals": [
            {
                "name": g.name,
                "position": list(g.position),
                "reached": list(g.reached) if g.reached else None,
                "error_cm": g.error_cm,
                "satisfied": g.satisfied,
            }
            for g in view.goals
        ],
        "rig_files": {k[1][:12]: v for k, v in state.SESSION.rig_files.items()},
        "file_ids": list(state.SESSION.rig_files.values()),
        "_": bool(ops),
    }


def setup_scene(start: int = 1, end: int = 97, fps: int = 24) -> bpy.types.Scene:
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = fps, 1.0
    sc.frame_start, sc.frame_end = start, end
    return sc


def select_only(objs: list[bpy.types.Object]) -> None:
    for o in bpy.context.scene.objects:
        o.select_set(False)
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0]


def connect() -> None:
    assert bpy.ops.segue.connect(url=CFG["url"]) == {"FINISHED"}


def generate(**kw: object) -> float:
    t = time.perf_counter()
    assert bpy.ops.segue.generate(wait=True, **kw) == {"FINISHED"}
    return time.perf_counter() - t


# -- scenarios ------------------------------------------------------------------------------------
def scenario_goals() -> dict:
    """The held-out bar: a skinned character of its own, two goal empties on the floor, connect and
    generate with scene goals; what the rig and its action became."""
    sc = setup_scene()
    char = rigs.ferry() if CFG.get("rig") == "ferry" else rigs.courier()
    start, end = CFG["goals"]
    goal("Start", sc.frame_start, tuple(start))
    goal("End", sc.frame_end, tuple(end), CFG.get("end_facing"))
    select_only([char])
    before = rig_state(char)
    connect()
    assert bpy.ops.segue.detect_roles() == {"FINISHED"}
    roles = {r: getattr(char.segue_roles, r) for r in addon_module("roles").ROLES}
    wall = generate(database=CFG["database"], scene_goals=True)
    after = rig_state(char)
    frames = [sc.frame_start, (sc.frame_start + sc.frame_end) // 2, sc.frame_end]
    names = addon_module("scene").upload_names(char)
    return {
        "rig": char.name,
        "roles": roles,
        "upload_names": names,
        "bones_unchanged": before["bones"] == after["bones"],
        "meshes_unchanged": before["meshes"] == after["meshes"],
        "object_unchanged": before["matrix_world"] == after["matrix_world"],
        "deform_bones": [b.name for b in char.data.bones if b.use_deform],
        "action": action_report(char),
        "frames": frames,
        "heads": heads_at(char, frames),
        "hips": roles["Hips"],
        "mesh_moved_end": mesh_motion(char, sc.frame_end),
        "job": job_report(),
        "wall_s": wall,
        "fps": sc.render.fps,
    }


SCENARIOS = {
    name.removeprefix("scenario_"): fn for name, fn in list(globals().items()) if name.startswith("scenario_")
}

if __name__ == "__main__":
    bpy.ops.wm.read_factory_settings(use_empty=True)
    module = install(CFG["zip"], CFG.get("install", "extension"))
    result = {"addon_module": module, "blender": bpy.app.version_string}
    result.update(SCENARIOS[CFG["scenario"]]())
    OUT.write_text(json.dumps(result))
