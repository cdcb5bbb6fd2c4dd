"""Figures of a retargeted character's feet measured on its own skinned mesh, as a viewer plays
the output file: the mesh deformed by linear blend skinning (:mod:`motion.skinning`, checked
against Blender's deformation by ``tests/motion/test_feet_blender.py``) under the file's first
animation. Used by ``tests/motion/retarget/test_feet_mesh.py`` and ``bench/feet_mesh.py``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import numpy as np

from motion import Motion
from motion.contacts import foot_plants
from motion.export.bind import bound_glb
from motion.export.events import contact_events
from motion.retarget import correspond, detect_roles, retarget
from motion.retarget.character import gltf_character
from motion.retarget.legik import character_soles, foot_groups_of, sole_floor
from motion.retarget.report import fastest_foot, sole_plants
from motion.retarget.rootmotion import default_root_motion
from motion.retarget.transfer import leg_length, zero_pose
from motion.skinning import animation_pose, read_skinned_mesh, skin

from .namings import ROLE_OF_UNREAL, name_in

CHUNK = 128  # frames skinned at a time


def written(source: Motion, raw: bytes, name_map: dict[str, str] | None = None) -> bytes:
    """``source`` retargeted onto the glTF character ``raw`` and written into its own file with
    its contact events, as ``segue retarget SOURCE --to CHAR.glb --out OUT.glb --events contacts
    [--map MAP]`` writes it (root motion as for glTF, feet locked, events where the soles touch)."""
    character = gltf_character(raw)
    mesh = read_skinned_mesh(raw)
    corr = correspond(source.skeleton, character.skeleton, name_map)
    mode = default_root_motion("gltf", corr.target_roles["Hips"])
    out = retarget(source, character, name_map=name_map, root_motion=mode, mesh=mesh)
    groups = foot_groups_of(corr.target_roles)
    soles = character_soles(character, corr.target_roles, mesh)
    plants = sole_plants(out, groups, soles, sole_floor(out, soles, character, corr.target_roles))
    return bound_glb(raw, out, events=contact_events(out, feet=groups, plants=plants))


def _subtree(parents: list[int], top: int) -> np.ndarray:
    inside = np.zeros(len(parents), dtype=bool)
    inside[top] = True
    for j in range(len(parents)):
        k = parents[j]
        while k >= 0 and not inside[j]:
            inside[j] = inside[k]
            k = parents[k]
    return inside


def _doc(raw: bytes) -> dict[str, Any]:
    n = int.from_bytes(raw[12:16], "little")
    return dict(json.loads(raw[20 : 20 + n]))


def measure(
    out_glb: bytes,
    source: Motion,
    rest: Motion,
    naming: str,
    name_of: Callable[[str, str], str] = name_in,
) -> dict[str, Any]:
    """The figures of one output file (``out_glb``: ``source`` retargeted onto the character
    whose rest pose, in Unreal names, is ``rest``, its joints named after ``naming``: joint ``u``
    of ``rest`` is ``name_of(naming, u)`` in the file):

    * ``sink_cm``: how far the mesh goes under its rest floor (the bind pose's lowest vertex), at
      worst (``sink_frame``);
    * ``lift_cm``: over the frames of the file's contact events, how far the planted foot's lowest
      vertex (vertices weighted at least half to that foot and its toes) is above the rest floor,
      at worst (``lift_frame``), and ``lift_p95_cm``;
    * ``foot_speed_ratio``: the fastest foot joint (ankle or toe, frame to frame) over the source's
      fastest (:func:`motion.retarget.report.fastest_foot`: ankle and toe, or the foot's tip
      without a toe joint) scaled by the leg-length ratio (thigh plus shin in the rest poses);
    * ``contacts`` (and ``contacts_off_feet``, events naming no foot), ``source_plants``,
      ``contacts_per_plant``.
    """
    mesh = read_skinned_mesh(out_glb)
    if mesh is None:
        raise SystemExit("the output has no skinned mesh")
    index = next((k for k, a in enumerate(_doc(out_glb)["animations"]) if "extras" in a), 0)
    names, pos, rots, times = animation_pose(out_glb, index)
    mesh = mesh.reindexed(names)
    fps = (times.size - 1) / max(float(times[-1] - times[0]), 1e-9)
    doc = _doc(out_glb)
    node_of = {str(doc["nodes"][j].get("name")): k for k, j in enumerate(doc["skins"][0]["joints"])}
    parent_node = {int(c): i for i, nd in enumerate(doc["nodes"]) for c in nd.get("children", [])}
    joint_nodes = [int(j) for j in doc["skins"][0]["joints"]]
    index_of_node = {n: k for k, n in enumerate(joint_nodes)}
    parents = []
    for n in joint_nodes:
        p = parent_node.get(n)
        while p is not None and p not in index_of_node:
            p = parent_node.get(p)
        parents.append(-1 if p is None else index_of_node[p])
    sides: dict[str, tuple[int, ...]] = {}
    for side, s in (("Left", "l"), ("Right", "r")):
        sides[side] = tuple(
            node_of[name_of(naming, u)] for u in (f"foot_{s}", f"ball_{s}") if name_of(naming, u) in node_of
        )
    foot_vertices = {}
    for side, joints in sides.items():
        inside = _subtree(parents, joints[0])
        foot_vertices[side] = np.flatnonzero(
            np.where(inside[mesh.joints], mesh.weights, 0.0).sum(axis=1) >= 0.5
        )
    bind = skin(mesh, mesh.bind_positions[None], mesh.bind_rotations[None])[0]
    floor = float(bind[:, 1].min())
    n = pos.shape[0]
    lowest = np.empty(n)
    foot_low = {side: np.empty(n) for side in sides}
    for a in range(0, n, CHUNK):
        v = skin(mesh, pos[a : a + CHUNK], rots[a : a + CHUNK])
        lowest[a : a + CHUNK] = v[:, :, 1].min(axis=1)
        for side, idx in foot_vertices.items():
            foot_low[side][a : a + CHUNK] = v[:, idx, 1].min(axis=1)
    # contacts: the file's events, each on the side whose foot or toe it names
    anim = next((a for a in doc["animations"] if "extras" in a), doc["animations"][0])
    events = [e for e in anim.get("extras", {}).get("events", []) if e["type"] == "contact"]
    side_of = {names[j]: side for side, joints in sides.items() for j in joints}
    planted = {side: np.zeros(n, dtype=bool) for side in sides}
    for e in events:  # (an event on a joint of neither foot, e.g. an ik_foot_root, is counted only)
        a = int(round(float(e["time_s"]) * fps))
        b = a + int(round(float(e["duration_s"]) * fps))
        if e["joint"] in side_of:
            planted[side_of[e["joint"]]][a:b] = True
    lifts = np.concatenate([foot_low[s][planted[s]] - floor for s in sides]) if events else np.zeros(0)
    frames = np.concatenate([np.flatnonzero(planted[s]) for s in sides]) if events else np.zeros(0, int)
    # foot speeds: the output's ankles and toes against the source's, scaled by leg length
    feet = [j for joints in sides.values() for j in joints]
    speed = np.linalg.norm(np.diff(pos[:, feet], axis=0), axis=-1) * fps  # metres
    src_roles = detect_roles(source.skeleton).joints
    src_speed = fastest_foot(source, src_roles)  # its ankles and toes (a foot's tip without a toe)
    rest_roles = {ROLE_OF_UNREAL[u]: k for k, u in enumerate(rest.skeleton.names) if u in ROLE_OF_UNREAL}
    scale = leg_length(rest.global_positions()[0] * rest.metres_per_unit, rest_roles) / leg_length(
        zero_pose(source).global_positions()[0] * source.metres_per_unit, src_roles
    )
    f, k = np.unravel_index(int(np.argmax(speed)), speed.shape)
    plants = len(foot_plants(source))
    return {
        "frames": n,
        "sink_cm": round(100.0 * max(floor - float(lowest.min()), 0.0), 2),
        "sink_frame": int(np.argmin(lowest)),
        "lift_cm": round(100.0 * float(lifts.max()), 2) if lifts.size else None,
        "lift_p95_cm": round(100.0 * float(np.percentile(lifts, 95)), 2) if lifts.size else None,
        "lift_frame": int(frames[np.argmax(lifts)]) if lifts.size else None,
        "foot_speed_m_s": round(float(speed.max()), 2),
        "foot_speed_frame": int(f) + 1,
        "foot_speed_joint": names[feet[k]],
        "source_foot_speed_scaled_m_s": round(src_speed * scale, 2),
        "foot_speed_ratio": round(float(speed.max()) / (src_speed * scale), 3),
        "contacts": len(events),
        "contacts_off_feet": sum(e["joint"] not in side_of for e in events),
        "source_plants": plants,
        "contacts_per_plant": round(len(events) / plants, 3) if plants else None,
    }
