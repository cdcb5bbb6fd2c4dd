"""Run with Blender's Python (``$SEGUE_BPY_PYTHON scenario.py -- CONFIG.json OUT.json``;
tests/blender.py): install the add-on zip ``segue blender-addon`` wrote, build the test characters
(rigs.py), run one scenario of the add-on against a running ``segue serve`` and write what came
out as JSON for the test to check (tests/integrations/test_blender_addon.py).

CONFIG holds ``zip``, ``install`` (``extension`` or ``legacy``), ``url``, ``scenario`` and the
scenario's own keys (database ids, files). Positions in OUT are Blender world metres (Z up)."""

from __future__ import annotations

import json
import math
import os
import sys
import time
from itertools import pairwise
from pathlib import Path

import bpy
from mathutils import Vector

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
    return next(a.module for a in bpy.context.preferences.addons if a.module.endswith("segue_blender"))


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


# -- pictures (Workbench, headless) ---------------------------------------------------------------
def _material_color(obj: bpy.types.Object, rgba: tuple[float, float, float, float]) -> None:
    obj.color = rgba


def _marker(
    name: str, at: tuple[float, float, float], rgba: tuple[float, float, float, float], r: float = 0.18
) -> None:
    bpy.ops.mesh.primitive_cylinder_add(radius=r, depth=0.02, location=(at[0], at[1], 0.01))
    ob = bpy.context.active_object
    ob.name = name
    _material_color(ob, rgba)


def _trail(
    name: str, points: list[list[float]], rgba: tuple[float, float, float, float], width: float = 0.025
) -> None:
    cu = bpy.data.curves.new(name, "CURVE")
    cu.dimensions = "3D"
    cu.bevel_depth = width
    sp = cu.splines.new("POLY")
    sp.points.add(len(points) - 1)
    for pt, p in zip(sp.points, points, strict=True):
        pt.co = (p[0], p[1], 0.05, 1.0)
    ob = bpy.data.objects.new(name, cu)
    bpy.context.scene.collection.objects.link(ob)
    _material_color(ob, rgba)


def picture(
    path: str,
    frame: int,
    chars: list[bpy.types.Object],
    goals: list[dict],
    trails: list[list[list[float]]],
    curves: tuple[bpy.types.Object, ...] = (),
) -> str:
    """A Workbench render of the scene at ``frame``: the characters (their skinned meshes), each
    goal a disc (green met, red missed) on a floor, each hips trail a blue line, ``curves`` (an
    authored path) drawn orange; the camera frames them all."""
    sc = bpy.context.scene
    sc.frame_set(frame)
    for g in goals:
        _marker(
            f"goal {g['name']}", g["position"], (0.1, 0.75, 0.25, 1) if g["satisfied"] else (0.9, 0.1, 0.1, 1)
        )
    for k, t in enumerate(trails):
        if len(t) > 1:
            _trail(f"trail {k}", t, (0.15, 0.35, 0.95, 1), width=0.018)
    for c in curves:
        c.data.bevel_depth = 0.045
        _material_color(c, (1.0, 0.55, 0.0, 1))
    pts = [Vector(p) for t in trails for p in t] + [Vector(g["position"]) for g in goals]
    pts += [c.matrix_world @ b.head for c in chars for b in c.pose.bones]
    lo = Vector((min(p.x for p in pts), min(p.y for p in pts), 0.0))
    hi = Vector((max(p.x for p in pts), max(p.y for p in pts), 1.8))
    centre = (lo + hi) / 2
    size = max(hi.x - lo.x, hi.y - lo.y, 2.0)
    bpy.ops.mesh.primitive_plane_add(size=size * 3, location=(centre.x, centre.y, 0.0))
    _material_color(bpy.context.active_object, (0.82, 0.82, 0.80, 1))
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.data.lens = 35
    direction = Vector((0.35, -1.0, 0.75)).normalized()
    cam.location = centre + direction * (size * 1.55 + 2.0)
    cam.rotation_euler = (centre - cam.location).to_track_quat("-Z", "Y").to_euler()
    sc.render.engine = "BLENDER_WORKBENCH"
    shading = sc.display.shading
    shading.light = "STUDIO"
    shading.color_type = "OBJECT"
    shading.show_shadows = True
    shading.show_cavity = True
    sc.render.resolution_x, sc.render.resolution_y = 960, 540
    sc.render.film_transparent = False
    sc.render.filepath = path
    for c in chars:
        for m in sc.objects:
            if m.type == "MESH" and m.parent == c:
                _material_color(m, (0.85, 0.62, 0.45, 1))
    bpy.ops.render.render(write_still=True)
    return path


def _hips_trail(char: bpy.types.Object, start: int, end: int) -> list[list[float]]:
    hips = char.segue_roles.Hips
    return [h[hips] for h in heads_at(char, list(range(start, end + 1, 2)))]


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
    report = job_report()
    heads = heads_at(char, frames)
    moved = mesh_motion(char, sc.frame_end)
    shot = None
    if CFG.get("picture"):
        trail = _hips_trail(char, sc.frame_start, sc.frame_end)
        shot = picture(
            CFG["picture"], (sc.frame_start + 2 * sc.frame_end) // 3, [char], report["goals"], [trail]
        )
    return {
        "picture": shot,
        "rig": char.name,
        "roles": roles,
        "upload_names": names,
        "bones_unchanged": before["bones"] == after["bones"],
        "meshes_unchanged": before["meshes"] == after["meshes"],
        "object_unchanged": before["matrix_world"] == after["matrix_world"],
        "deform_bones": [b.name for b in char.data.bones if b.use_deform],
        "action": action_report(char),
        "frames": frames,
        "heads": heads,
        "hips": roles["Hips"],
        "mesh_moved_end": moved,
        "job": report,
        "wall_s": wall,
        "fps": sc.render.fps,
    }


def _walk_action(char: bpy.types.Object, start: tuple, end: tuple) -> None:
    """Give ``char`` a walk from ``start`` to ``end`` over the scene (a graph job on the walks)."""
    sc = bpy.context.scene
    goal("Walk start", sc.frame_start, start)
    goal("Walk end", sc.frame_end, end)
    select_only([char])
    generate(database=CFG["database"], scene_goals=True)
    for o in [o for o in sc.objects if o.type == "EMPTY"]:
        bpy.data.objects.remove(o)


def scenario_upload_build() -> dict:
    """An action on the artist's rig (here one Segue made, from the walks) uploaded as a clip, a
    graph database built from it, and another character generating from that database."""
    sc = setup_scene(1, 97)
    courier = rigs.courier()
    ferry = rigs.ferry(location=(-1.0, 2.0, 0.0))
    connect()
    _walk_action(courier, (1.0, -0.5, 0.0), (3.5, -1.5, 0.0))
    select_only([courier])
    courier.animation_data.action.pose_markers.new("walk").frame = 1
    courier.animation_data.action.pose_markers.new("!run").frame = 49
    assert bpy.ops.segue.upload_action(name="courier-walk.bvh") == {"FINISHED"}
    state = addon_module("state")
    clip = next(c for c in state.SESSION.clips if c["name"] == "courier-walk.bvh")
    assert bpy.ops.segue.build_database(
        kind="graph", clips="courier-walk.bvh", name="courier walks", wait=True
    ) == {"FINISHED"}
    db = sc.segue.database
    select_only([ferry])
    sc.frame_start, sc.frame_end = 1, 49
    generate(database=db, request=json.dumps({"frames": 61, "seed": 2}))
    hips = ferry.segue_roles.Hips
    heads = heads_at(ferry, [1, 49])
    return {
        "clip": clip,
        "labels": state.SESSION.clip_labels.get("courier-walk.bvh"),
        "database": db,
        "action": action_report(ferry),
        "job": job_report(),
        "hips_moved": (Vector(heads[1][hips]) - Vector(heads[0][hips])).length,
        "deform_bones": [b.name for b in ferry.data.bones if b.use_deform],
    }


def _curve(name: str, points: list[tuple[float, float, float]]) -> bpy.types.Object:
    cu = bpy.data.curves.new(name, "CURVE")
    cu.dimensions = "3D"
    sp = cu.splines.new("BEZIER")
    sp.bezier_points.add(len(points) - 1)
    for bp, p in zip(sp.bezier_points, points, strict=True):
        bp.co = p
        bp.handle_left_type = bp.handle_right_type = "AUTO"
    ob = bpy.data.objects.new(name, cu)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _floor_distance(p: list[float], poly: list[tuple[float, float, float]]) -> float:
    best = 1e9
    for a, b in pairwise(poly):
        ax, ay, bx, by = a[0], a[1], b[0], b[1]
        dx, dy = bx - ax, by - ay
        L = dx * dx + dy * dy
        u = 0.0 if L == 0 else max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / L))
        best = min(best, math.hypot(p[0] - ax - u * dx, p[1] - ay - u * dy))
    return best


def scenario_path() -> dict:
    """A curve is the walked path of a walk database (Path tool): the hips follow it."""
    setup_scene(1, 121)
    char = rigs.courier()
    path = _curve("Path", [(0.0, 0.0, 0.0), (1.5, -1.0, 0.0), (2.0, -3.0, 0.0), (3.5, -4.5, 0.0)])
    select_only([char])
    connect()
    generate(database=CFG["database"], scene_goals=True, path=path.name, speed=1.2)
    scene_mod = addon_module("scene")
    poly = scene_mod.curve_points(path)
    hips = char.segue_roles.Hips
    act = char.animation_data.action
    last = int(act.frame_range[1])
    frames = list(range(1, last + 1, 4))
    heads = heads_at(char, frames)
    dist = [_floor_distance(h[hips], poly) for h in heads]
    end = heads[-1][hips]
    shot = (
        picture(CFG["picture"], last * 2 // 3, [char], [], [[h[hips] for h in heads]], (path,))
        if CFG.get("picture")
        else None
    )
    return {
        "picture": shot,
        "action": action_report(char),
        "job": job_report(),
        "distances": dist,
        "end_to_path_end": math.hypot(end[0] - poly[-1][0], end[1] - poly[-1][1]),
        "start_to_path_start": math.hypot(heads[0][hips][0] - poly[0][0], heads[0][hips][1] - poly[0][1]),
    }


def scenario_timeline() -> dict:
    """Timeline markers named after labels paint an annotation timeline (Timeline tool)."""
    sc = setup_scene(1, 193)  # 8 s at 24 fps
    char = rigs.courier()
    sc.timeline_markers.new("walk, !jump", frame=1)
    sc.timeline_markers.new("run, !jump", frame=121)
    select_only([char])
    connect()
    generate(database=CFG["database"], scene_goals=True, request=json.dumps({"seed": 3}))
    return {"action": action_report(char), "job": job_report()}


def _click_track(path: str, bpm: float, seconds: float, rate: int = 22050) -> None:
    """A WAV recording of a click on every beat (written here, nothing downloaded)."""
    import struct
    import wave

    n = int(seconds * rate)
    period = 60.0 / bpm
    frames = bytearray()
    for k in range(n):
        t = k / rate
        phase = t % period
        v = math.sin(2 * math.pi * 1000 * t) * math.exp(-phase * 40) if phase < 0.08 else 0.0
        frames += struct.pack("<h", int(20000 * v))
    with wave.open(path, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(bytes(frames))


def scenario_music() -> dict:
    """The scene's sound strip is the music of a rhythm database (Music tool)."""
    sc = setup_scene(1, 193)
    char = rigs.courier()
    wav = str(Path(CFG["tmp"]) / "clicks.wav")
    _click_track(wav, CFG.get("bpm", 120.0), 8.5)
    ed = sc.sequence_editor_create()
    strips = ed.strips if hasattr(ed, "strips") else ed.sequences  # Blender 5 renamed them
    strips.new_sound("clicks", wav, 1, 1)
    select_only([char])
    connect()
    generate(database=CFG["database"], scene_goals=True)
    return {"action": action_report(char), "job": job_report()}


def scenario_partner() -> dict:
    """Another armature's action leads a Partner (control) database: a leader imported with
    Blender's own BVH importer, a follower generated on the artist's character."""
    sc = setup_scene(1, 10)
    bpy.ops.import_anim.bvh(
        filepath=CFG["leader_bvh"],
        global_scale=CFG["leader_scale"],
        update_scene_fps=True,
        update_scene_duration=True,
    )
    leader = bpy.context.active_object
    leader.name = "Leader"
    end = min(sc.frame_end, sc.frame_start + 8 * int(sc.render.fps))  # the first 8 s of the dance
    sc.frame_end = end
    char = rigs.courier(location=(0.8, 0.0, 0.0))
    select_only([char])
    connect()
    generate(database=CFG["database"], scene_goals=True, leader=leader.name)
    frames = list(range(sc.frame_start, sc.frame_end + 1, 10))
    lead_hips = [h["hip"] for h in heads_at(leader, frames)]
    hips = char.segue_roles.Hips
    follow = [h[hips] for h in heads_at(char, frames)]
    gaps = [math.hypot(a[0] - b[0], a[1] - b[1]) for a, b in zip(lead_hips, follow, strict=True)]
    return {"action": action_report(char), "job": job_report(), "gaps": gaps,
            "leader_travel": (Vector(lead_hips[-1]) - Vector(lead_hips[0])).length}  # fmt: skip


def scenario_dancers() -> dict:
    """One armature per dancer (crowds, couples, several graph characters): each gets its own
    action from its own part of the result."""
    sc = setup_scene(1, CFG.get("end", 97))
    chars = [rigs.courier(location=(0.0, 0.0, 0.0), turn_deg=0.0, name="Ada"),
             rigs.ferry(location=(2.0, 0.0, 0.0), name="Bo")]  # fmt: skip
    if CFG.get("three"):
        chars.append(rigs.courier(location=(-2.0, 0.0, 0.0), turn_deg=180.0, name="Cy"))
    for d, (start, end) in enumerate(CFG.get("goals", [])):
        goal(f"Start {d}", sc.frame_start, tuple(start), dancer=d)
        goal(f"End {d}", sc.frame_end, tuple(end), dancer=d)
    select_only(chars)
    connect()
    generate(database=CFG["database"], scene_goals=True, request=json.dumps(CFG.get("request", {})),
             armatures=",".join(c.name for c in chars), bpm=CFG.get("bpm", 0.0))  # fmt: skip
    frames = [sc.frame_start, sc.frame_end]
    out = []
    for c in chars:
        hips = c.segue_roles.Hips
        heads = heads_at(c, frames)
        deform = [b.name for b in c.data.bones if b.use_deform]
        out.append(
            {
                "name": c.name,
                "action": action_report(c),
                "hips": [h[hips] for h in heads],
                "deform_bones": deform,
            }
        )
    report = job_report()
    shot = None
    if CFG.get("picture"):
        trails = [_hips_trail(c, sc.frame_start, sc.frame_end) for c in chars]
        shot = picture(CFG["picture"], (sc.frame_start + sc.frame_end) // 2, chars, report["goals"], trails)
    return {"dancers": out, "job": report, "picture": shot}


def _pump(until: float = 120.0) -> list[str]:
    """Run the add-on's timer as Blender's event loop would (a Python-module Blender has none),
    until it stops; the job's states seen (a hang guard of ``until`` seconds)."""
    ops = addon_module("ops")
    state = addon_module("state")
    seen = []
    deadline = time.monotonic() + until
    while ops._timer() is not None:
        view = state.SESSION.job
        if not seen or seen[-1] != view.state:
            seen.append(view.state)
        if time.monotonic() > deadline:
            raise AssertionError("the job did not end (hang guard)")
        time.sleep(0.02)
    seen.append(state.SESSION.job.state)  # what the last call applied
    return seen


def scenario_live() -> dict:
    """Generate without waiting: the operator returns at once and the timer keys each solution as
    it arrives; Cancel keeps the best so far."""
    setup_scene(1, 97)
    char = rigs.courier()
    goal("Start", 1, (1.0, -0.5, 0.0))
    goal("End", 97, (3.3, -2.0, 0.0))
    select_only([char])
    connect()
    state = addon_module("state")
    assert bpy.ops.segue.generate(database=CFG["database"], scene_goals=True) == {"FINISHED"}
    at_return = state.SESSION.job.state
    states = _pump()
    done = {"at_return": at_return, "states": states, "job": job_report(), "action": action_report(char)}
    # a long search, cancelled once its first solution shows: the best so far stays on the rig.
    # Long by its work, not only its budget (a search also ends when it converges, and the short
    # one above converges within a second on an idle machine): a minute of motion, the end goal
    # 40 m away, so each round costs ~20 times more and the cancel arrives long before convergence
    setup_scene(1, 1441)
    bpy.data.objects["End"]["segue_frame"] = 1441
    bpy.data.objects["End"].location = (30.0, -28.0, 0.0)
    long = json.dumps({"rounds": None, "budget_s": 300})
    assert bpy.ops.segue.generate(database=CFG["database"], scene_goals=True, request=long) == {"FINISHED"}
    ops = addon_module("ops")
    deadline = time.monotonic() + 120
    while state.SESSION.job.solutions == 0:
        if ops._timer() is None or time.monotonic() > deadline:
            raise AssertionError(f"no solution before the job ended: {state.SESSION.job.state}")
        time.sleep(0.02)
    assert bpy.ops.segue.cancel() == {"FINISHED"}
    _pump()
    return {"done": done, "cancelled": {"job": job_report(), "action": action_report(char)}}


def scenario_local() -> dict:
    """The add-on's preferences start a local service (`segue serve --import DIR` on a free port)
    from a `segue` executable; it serves the imported database; stop stops it; another one is
    left running for Blender's exit to stop."""
    setup_scene(1, 31)
    char = rigs.courier()
    select_only([char])
    prefs = bpy.context.preferences.addons[
        next(a.module for a in bpy.context.preferences.addons if a.module.endswith("segue_blender"))
    ].preferences
    prefs.segue_executable = CFG["segue"]
    prefs.data_dir = str(Path(CFG["tmp"]) / "local-data")
    prefs.import_dirs = CFG["import_dir"]
    assert bpy.ops.segue.start_local() == {"FINISHED"}
    state = addon_module("state")
    first = {"url": state.SESSION.url, "pid": state.SESSION.local.process.pid,
             "databases": [d["id"] for d in state.SESSION.databases]}  # fmt: skip
    generate(
        database=CFG["database"],
        request=json.dumps({"engine": "clip", "clip": "walk", "start": 0, "end": 30}),
    )
    first["job"] = job_report()
    first["action"] = action_report(char)
    assert bpy.ops.segue.stop_local() == {"FINISHED"}
    stopped_pid = first["pid"]
    assert bpy.ops.segue.start_local() == {"FINISHED"}
    return {"first": first, "stopped_pid": stopped_pid, "left_running_pid": state.SESSION.local.process.pid}


SCENARIOS = {
    name.removeprefix("scenario_"): fn for name, fn in list(globals().items()) if name.startswith("scenario_")
}

if __name__ == "__main__":
    bpy.ops.wm.read_factory_settings(use_empty=True)
    module = install(CFG["zip"], CFG.get("install", "extension"))
    result = {"addon_module": module, "blender": bpy.app.version_string}
    result.update(SCENARIOS[CFG["scenario"]]())
    OUT.write_text(json.dumps(result))
    if bpy.app.version < (4, 4) and CFG["scenario"] != "local":
        # bpy 4.2 as a Python module segfaults in its own teardown at exit (after a glTF export or
        # a render, the add-on or not); the output is written, so leave without it (the "local"
        # scenario, which checks what Blender's exit stops, runs its exit)
        os._exit(0)
