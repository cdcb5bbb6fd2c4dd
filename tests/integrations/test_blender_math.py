"""The add-on's plain-Python parts (no Blender): its matrices, GLB reading, the binding of a result
to an armature, the clip conversion and the scene's requests, checked against Segue's own numpy
code (forward kinematics, the BVH reader, the glTF writer and binder)."""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from integrations.blender.segue_blender import authoring, axes, binding, bvh, gltf, mat4, roles
from motion import read_bvh
from motion.export.bind import bound_glb
from motion.export.glb import glb_bytes
from motion.io import load_motion
from motion.retarget import retarget
from motion.retarget.character import gltf_character

RNG = np.random.default_rng(7)


def _np(m: mat4.Mat4) -> np.ndarray:
    return np.array(m).reshape(4, 4)


def _tuple(a: np.ndarray) -> mat4.Mat4:
    return tuple(float(v) for v in a.reshape(16))


# -- matrices -------------------------------------------------------------------------------------
@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_euler_angles_round_trip_and_match_scipy(order: str) -> None:
    for q in Rotation.random(50, random_state=3).as_quat():
        r = mat4.matrix3_of_quat(q)
        angles = mat4.euler_from_matrix3(r, order)
        back = np.array(mat4.matrix3_of_euler(angles, order)).reshape(3, 3)
        np.testing.assert_allclose(back, np.array(r).reshape(3, 3), atol=1e-9)
        np.testing.assert_allclose(back, Rotation.from_euler(order, angles).as_matrix(), atol=1e-9)


def test_trs_products_and_inverse_match_numpy() -> None:
    for _ in range(20):
        q = Rotation.random(random_state=RNG.integers(1 << 30)).as_quat()
        t, s = RNG.normal(size=3), RNG.uniform(0.01, 3, size=3)
        m = mat4.from_trs(t, q, s)
        ref = np.eye(4)
        ref[:3, :3] = Rotation.from_quat(q).as_matrix() * s
        ref[:3, 3] = t
        np.testing.assert_allclose(_np(m), ref, atol=1e-12)
        np.testing.assert_allclose(_np(mat4.inverse(m)), np.linalg.inv(ref), atol=1e-9)
        other = mat4.from_trs(RNG.normal(size=3), Rotation.random(random_state=1).as_quat(), (1, 1, 1))
        np.testing.assert_allclose(_np(mat4.mul(m, other)), ref @ _np(other), atol=1e-12)
        q2 = mat4.rotation_of(m)
        assert abs(abs(float(np.dot(q2, q))) - 1) < 1e-9


def test_a_singular_matrix_is_an_error() -> None:
    with pytest.raises(ValueError, match="singular"):
        mat4.inverse(mat4.from_trs((0, 0, 0), (0, 0, 0, 1), (1, 0, 1)))


# -- axes -----------------------------------------------------------------------------------------
def test_blender_and_segue_axes() -> None:
    assert axes.to_segue((1.0, 2.0, 3.0)) == (1.0, 3.0, -2.0)
    assert axes.to_blender(axes.to_segue((1.0, 2.0, 3.0))) == (1.0, 2.0, 3.0)
    assert axes.heading_deg((0.0, -1.0)) == pytest.approx(0.0)  # Blender's forward (-Y) is Segue's +Z
    assert axes.heading_deg((1.0, 0.0)) == pytest.approx(90.0)
    assert axes.heading_deg((0.0, 1.0)) == pytest.approx(180.0)
    np.testing.assert_allclose(axes.blender_direction(90.0), (1.0, 0.0), atol=1e-12)
    frame = axes.SegueFrame((1.0, 2.0), 1.25)
    assert frame.floor((1.0, 2.0, 0.0)) == (0.0, -0.0)
    assert frame.floor((3.5, 2.0, 0.0)) == pytest.approx((2.0, 0.0))
    assert frame.floor((1.0, 4.5, 0.0)) == pytest.approx((0.0, -2.0))  # Blender +Y is Segue -Z
    with pytest.raises(ValueError, match="vertical"):
        axes.heading_deg((0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="scale"):
        axes.SegueFrame((0, 0), 0.0)


# -- GLB ------------------------------------------------------------------------------------------
def test_glb_nodes_accessors_and_renaming() -> None:
    walk = load_motion("sample:walk").slice(0, 20)
    raw = glb_bytes(walk)
    doc, binary = gltf.split_glb(raw)
    nodes = gltf.nodes_of(doc)
    joints = gltf.skin_joints(doc)
    anim = gltf.animation(doc, binary)
    assert len(anim.times) == 20
    assert anim.times[1] == pytest.approx(1 / walk.fps, rel=1e-6)
    names = [nodes[j].name for j in joints]
    renamed = gltf.rename_nodes(raw, {names[1]: "Hips"})
    doc2, bin2 = gltf.split_glb(renamed)
    assert bin2 == binary
    assert [n.name for n in gltf.nodes_of(doc2)][joints[1]] == "Hips"
    with pytest.raises(gltf.GltfError, match="two nodes"):
        gltf.rename_nodes(raw, {names[1]: names[2]})
    with pytest.raises(gltf.GltfError, match="not a GLB"):
        gltf.split_glb(b"solid cube")


def test_a_track_interpolates_between_keys() -> None:
    track = gltf.Track([0.0, 1.0], [(0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 1.0, 0.0)])
    half = track.at(0.5, rotation=True)
    assert half == pytest.approx((0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)))
    assert track.at(-1.0) == (0.0, 0.0, 0.0, 1.0)
    assert track.at(2.0) == (0.0, 0.0, 1.0, 0.0)


# -- a rig as Blender exports it: an armature node turned, scaled and moved -----------------------
def _wrapped(raw: bytes, armature_world: mat4.Mat4) -> bytes:
    """The GLB with its scene's nodes under an 'Armature' node of Blender world ``armature_world``
    (what Blender's glTF exporter writes for an armature object)."""
    doc, binary = gltf.split_glb(raw)
    node = np.array(mat4.mul(axes.GLTF_FROM_BLENDER, mat4.mul(armature_world, axes.BLENDER_FROM_GLTF)))
    scene = doc["scenes"][0]
    doc["nodes"].append({"name": "Armature", "children": list(scene["nodes"]),
                         "matrix": [float(v) for v in node.reshape(4, 4).T.reshape(16)]})  # fmt: skip
    scene["nodes"] = [len(doc["nodes"]) - 1]
    return gltf.join_glb(doc, binary)


def _bones_from(raw: bytes, armature_world: mat4.Mat4, roll_seed: int) -> dict[str, binding.RestBone]:
    """Blender-like rest bones of a GLB skin: head at the joint, Y along the bone towards its
    first child (or its parent's direction for a leaf), a random roll, in armature space."""
    doc, _ = gltf.split_glb(raw)
    nodes = gltf.nodes_of(doc)
    world = gltf.rest_world(nodes)
    joints = gltf.skin_joints(doc)
    inv_w = _np(mat4.inverse(armature_world))
    head = {n: (inv_w @ np.r_[axes.to_blender(mat4.translation(world[n])), 1.0])[:3] for n in joints}
    rng = np.random.default_rng(roll_seed)
    out = {}
    in_skin = set(joints)
    for n in joints:
        kids = [c for c in nodes[n].children if c in in_skin]
        p = nodes[n].parent if nodes[n].parent in in_skin else None
        if kids:
            y = head[kids[0]] - head[n]
        elif p is not None:
            y = head[n] - head[p]
        else:
            y = np.array([0.0, 0.0, 1.0])
        if np.linalg.norm(y) < 1e-9:
            y = np.array([0.0, 0.0, 1.0])
        y = y / np.linalg.norm(y)
        x = np.cross(y, rng.normal(size=3))
        x /= np.linalg.norm(x)
        z = np.cross(x, y)
        m = np.eye(4)
        m[:3, :3] = np.column_stack([x, y, z])
        m[:3, 3] = head[n]
        out[nodes[n].name] = binding.RestBone(
            nodes[n].name, nodes[p].name if p is not None else None, _tuple(m)
        )
    return out


def _armature_world(turn_deg: float, scale: float, at: tuple[float, float, float]) -> mat4.Mat4:
    m = np.eye(4)
    m[:3, :3] = Rotation.from_euler("xz", [90.0, turn_deg], degrees=True).as_matrix() * scale
    m[:3, 3] = at
    return _tuple(m)


@pytest.mark.parametrize(("turn", "scale"), [(0.0, 1.0), (90.0, 1.0), (-30.0, 0.01)])
def test_binding_puts_every_bone_where_segues_forward_kinematics_does(turn: float, scale: float) -> None:
    """The pose the add-on keys, from a bound GLB, puts each bone's head and tail at the joint
    positions Segue's FK gives the bound motion, in Blender's axes, whatever the armature object's
    transform and the bones' rest orientations (rolls)."""
    walk = load_motion("sample:walk-10-04")
    rest_pose = walk.slice(0, 1)
    world_a = _armature_world(turn, scale, (0.4, -1.2, 0.0))
    # a GLB skeleton in centimetres under the armature node (scale 0.01) holds the same metres
    char_glb = _wrapped(glb_bytes(rest_pose, ground_root=False), world_a)
    character = gltf_character(char_glb)
    motion = retarget(load_motion("sample:walk").slice(0, 45), character, root_motion="hips")
    bound = bound_glb(char_glb, motion, animation_only=True)
    rest = _bones_from(char_glb, world_a, roll_seed=int(turn) + 100)
    anchor = (2.0, -3.0)
    placement = axes.SegueFrame(anchor).placement()
    b = binding.plan(bound, {n: n for n in rest}, rest, world_a, placement)
    poses = binding.pose_matrices(b, binding.PlainOps())
    fk, _ = motion.fk()
    fk = fk * motion.metres_per_unit  # (F, J, 3) glTF axes, metres
    names = list(motion.skeleton.names)
    w = _np(world_a)
    worst = 0.0
    for name, seq in poses.items():
        j = names.index(name)
        for k in (0, 20, 44):
            head = (w @ _np(seq[k]) @ np.array([0.0, 0.0, 0.0, 1.0]))[:3]
            want = np.array(axes.to_blender(tuple(fk[k, j]))) + np.array([anchor[0], anchor[1], 0.0])
            worst = max(worst, float(np.abs(head - want).max()))
            kids = [c for c in range(len(names)) if motion.skeleton.parents[c] == j]
            if kids:  # the bone's Y axis points at its first child, as at rest
                rest_len = np.linalg.norm(
                    _np(rest[names[kids[0]]].matrix_local)[:3, 3] - _np(rest[name].matrix_local)[:3, 3]
                )
                tip = (w @ _np(seq[k]) @ np.array([0.0, rest_len, 0.0, 1.0]))[:3]
                want_tip = np.array(axes.to_blender(tuple(fk[k, kids[0]]))) + np.array(
                    [anchor[0], anchor[1], 0.0]
                )
                worst = max(worst, float(np.abs(tip - want_tip).max()))
    assert worst < 1e-4, worst  # float32 keys in the GLB
    # the basis matrices rebuild the poses through the bones' hierarchy
    basis = binding.basis_matrices(poses, rest)
    for name, seq in basis.items():
        parent = rest[name].parent
        for k in (0, 44):
            if parent is None:
                rebuilt = _np(rest[name].matrix_local) @ _np(seq[k])
            else:
                rel = np.linalg.inv(_np(rest[parent].matrix_local)) @ _np(rest[name].matrix_local)
                rebuilt = _np(poses[parent][k]) @ rel @ _np(seq[k])
            np.testing.assert_allclose(rebuilt, _np(poses[name][k]), atol=1e-9)


def test_binding_names_joints_that_are_no_bone() -> None:
    raw = glb_bytes(load_motion("sample:walk").slice(0, 3), ground_root=False)
    rest = _bones_from(raw, mat4.IDENTITY, 1)
    rest.pop("lFoot")
    with pytest.raises(binding.BindingError, match="lFoot"):
        binding.plan(raw, {n: n for n in [*rest, "lFoot"]}, rest, mat4.IDENTITY)


# -- clips ----------------------------------------------------------------------------------------
def test_a_glb_animation_becomes_a_bvh_segue_reads_with_the_same_joint_positions() -> None:
    walk = load_motion("sample:walk-05-01").slice(0, 40)
    world_a = _armature_world(35.0, 0.01, (1.0, 0.5, 0.0))
    raw = _wrapped(glb_bytes(walk, ground_root=False), world_a)
    text = bvh.glb_to_bvh(raw, fps=walk.fps)
    clip = read_bvh_text(text)
    assert clip.num_frames == 40
    assert clip.skeleton.names == walk.skeleton.names
    got = clip.global_positions() * clip.metres_per_unit
    # the source, placed by the armature object: Blender world -> Segue axes
    pos = walk.global_positions() * walk.metres_per_unit
    move = _np(mat4.mul(axes.GLTF_FROM_BLENDER, mat4.mul(world_a, axes.BLENDER_FROM_GLTF)))
    want = pos @ move[:3, :3].T + move[:3, 3]
    np.testing.assert_allclose(got, want, atol=2e-4)


def read_bvh_text(text: str):  # type: ignore[no-untyped-def]
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "clip.bvh"
        p.write_text(text)
        return read_bvh(p, units="m")


# -- roles ----------------------------------------------------------------------------------------
def _rig(
    spec: list[tuple[str, str | None, tuple[float, float, float], tuple[float, float, float]]],
) -> list[roles.Bone]:
    return [roles.Bone(n, p, h, t) for n, p, h, t in spec]


def _human(names: dict[str, str], turn_deg: float = 0.0) -> list[roles.Bone]:
    """A standing human facing -Y (left = +X), turned ``turn_deg`` about Z, bones named by ``names``."""
    c, s = math.cos(math.radians(turn_deg)), math.sin(math.radians(turn_deg))

    def r(p: tuple[float, float, float]) -> tuple[float, float, float]:
        return (c * p[0] - s * p[1], s * p[0] + c * p[1], p[2])

    spec = [
        ("hips", None, (0, 0, 0.95), (0, 0, 1.1)),
        ("spine", "hips", (0, 0, 1.1), (0, 0, 1.4)),
        ("neck", "spine", (0, 0, 1.45), (0, 0, 1.55)),
        ("head", "neck", (0, 0, 1.55), (0, 0, 1.75)),
    ]
    for side, sx in (("l", 1), ("r", -1)):
        spec += [
            (f"thigh_{side}", "hips", (0.1 * sx, 0, 0.93), (0.1 * sx, 0, 0.5)),
            (f"shin_{side}", f"thigh_{side}", (0.1 * sx, 0, 0.5), (0.1 * sx, 0.03, 0.08)),
            (f"foot_{side}", f"shin_{side}", (0.1 * sx, 0.03, 0.08), (0.1 * sx, -0.1, 0.02)),
            (f"toe_{side}", f"foot_{side}", (0.1 * sx, -0.1, 0.02), (0.1 * sx, -0.17, 0.02)),
            (f"clav_{side}", "spine", (0.02 * sx, 0, 1.4), (0.17 * sx, 0, 1.42)),
            (f"upper_{side}", f"clav_{side}", (0.18 * sx, 0, 1.42), (0.45 * sx, 0, 1.4)),
            (f"lower_{side}", f"upper_{side}", (0.45 * sx, 0, 1.4), (0.7 * sx, 0, 1.38)),
            (f"palm_{side}", f"lower_{side}", (0.7 * sx, 0, 1.38), (0.78 * sx, 0, 1.37)),
            (f"f1_{side}", f"palm_{side}", (0.78 * sx, -0.02, 1.37), (0.83 * sx, -0.02, 1.37)),
            (f"f2_{side}", f"palm_{side}", (0.78 * sx, 0.02, 1.37), (0.83 * sx, 0.02, 1.37)),
        ]
    return [roles.Bone(names.get(n, n), names.get(p, p) if p else None, r(h), r(t)) for n, p, h, t in spec]


@pytest.mark.parametrize("turn", [0.0, 90.0, 200.0])
def test_roles_are_found_by_shape_whatever_the_names_and_facing(turn: float) -> None:
    names = {
        f"{part}_{s}": f"x{i}{'ab'[k]}"
        for i, part in enumerate(["thigh", "shin", "foot", "toe", "clav", "upper", "lower", "palm"])
        for k, s in enumerate("lr")
    }
    found = roles.detect_roles(_human(names, turn))
    want = {"Hips": "hips", "Head": "head"}
    for k, side in enumerate(("Left", "Right")):
        for i, limb in enumerate(
            ["UpperLeg", "LowerLeg", "Foot", "Toes", "Shoulder", "UpperArm", "LowerArm", "Hand"]
        ):
            want[f"{side}{limb}"] = f"x{i}{'ab'[k]}"
    assert found == want
    assert roles.missing_roles(found) == []


def test_upload_names_rename_roles_and_keep_other_bones_out_of_their_way() -> None:
    bones = ["pelvis", "Hips", "leg.L", "spine"]
    names = roles.upload_names(bones, {"Hips": "pelvis", "LeftUpperLeg": "leg.L"})
    assert names == {"pelvis": "Hips", "Hips": "Hips_", "leg.L": "LeftUpperLeg", "spine": "spine"}
    with pytest.raises(roles.RoleError, match="two roles"):
        roles.upload_names(bones, {"Hips": "pelvis", "Head": "pelvis"})
    with pytest.raises(roles.RoleError, match="no bone"):
        roles.upload_names(bones, {"Hips": "nothing"})
    assert roles.missing_roles({"Hips": "pelvis"}) == list(roles.REQUIRED[1:])


# -- the scene's requests -------------------------------------------------------------------------
TIMING = authoring.Timing(1, 121, 24.0)


def test_goal_empties_become_body_constraints_in_segues_frame() -> None:
    goals = [
        authoring.Goal("end", 121, (3.0, 2.0, 0.0), facing=(1.0, 0.0)),
        authoring.Goal("start", 1, (1.0, -1.0, 0.0)),
    ]
    frame = axes.SegueFrame((1.0, -1.0), 1.1)
    out = authoring.scene_request(
        {"database": "d"}, {"kind": "graph", "fps": 30}, authoring.SceneInputs(TIMING, goals), frame
    )
    req = out.request
    assert out.start_frame == 1
    assert req["engine"] == "graph"
    assert req["frames"] == 151  # 5 s at 30 fps, first and last frames included
    first, last = req["constraints"]
    assert first == {"type": "body", "time_s": 0.0, "position": [0.0, 0.0]}
    assert last["time_s"] == pytest.approx(5.0)
    assert last["position"] == pytest.approx([2.0 / 1.1, -3.0 / 1.1])
    assert last["heading_deg"] == pytest.approx(90.0)
    json.dumps(req, allow_nan=False)


def test_a_goal_outside_the_frame_range_is_an_error_naming_it() -> None:
    goals = [authoring.Goal("late", 300, (0.0, 0.0, 0.0))]
    with pytest.raises(authoring.AuthoringError, match="'late' is at frame 300"):
        authoring.scene_request(
            {}, {"kind": "graph"}, authoring.SceneInputs(TIMING, goals), axes.SegueFrame()
        )


def test_a_curve_is_a_trajectory_timed_by_its_length_and_the_speed() -> None:
    path = [(0.0, 0.0, 0.0), (0.0, -3.0, 0.0), (2.0, -3.0, 0.0)]  # 5 m
    scene = authoring.SceneInputs(TIMING, path=path, speed=1.25)
    req = authoring.scene_request(
        {}, {"kind": "control", "control": "path"}, scene, axes.SegueFrame(scale=1.25)
    ).request
    traj = req["control"]["trajectory"]
    pts = np.array(traj["points"])
    assert traj["fps"] == 30.0
    assert len(pts) == 121  # 4 s at 1.25 m/s of the character, its 30 points a second
    np.testing.assert_allclose(pts[0], [0, 0])
    np.testing.assert_allclose(pts[-1], [2 / 1.25, 3 / 1.25], atol=1e-6)
    steps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    np.testing.assert_allclose(steps, 1.0 / 30, atol=1e-6)  # 1 m/s of the performers
    with pytest.raises(authoring.AuthoringError, match="needs a path"):
        authoring.scene_request(
            {}, {"kind": "control", "control": "path"}, authoring.SceneInputs(TIMING), axes.SegueFrame()
        )


def test_markers_paint_an_annotation_timeline() -> None:
    markers = [authoring.Marker("walk, !jump", 1), authoring.Marker("run", 49), authoring.Marker("~", 97)]
    scene = authoring.SceneInputs(TIMING, markers=markers)
    req = authoring.scene_request({}, {"kind": "annotated", "fps": 30}, scene, axes.SegueFrame()).request
    assert req["frames"] == 151
    assert req["timeline"] == [
        {"label": "walk", "start": 0, "end": 60, "value": 1},
        {"label": "jump", "start": 0, "end": 60, "value": -1},
        {"label": "run", "start": 60, "end": 120, "value": 1},
    ]


def test_music_and_dancers_make_a_rhythm_request() -> None:
    scene = authoring.SceneInputs(TIMING, bpm=118.0, dancers=3)
    req = authoring.scene_request({}, {"kind": "rhythm"}, scene, axes.SegueFrame()).request
    assert req["music"] == {"bpm": 118.0, "duration_s": 5.0}
    assert req["characters"] == 3
    scene = authoring.SceneInputs(TIMING, audio="f1d2", audio_start=25)
    req = authoring.scene_request({}, {"kind": "rhythm"}, scene, axes.SegueFrame()).request
    assert req["music"] == {"audio": "f1d2", "duration_s": 4.0}
    with pytest.raises(authoring.AuthoringError, match="needs music"):
        authoring.scene_request({}, {"kind": "rhythm"}, authoring.SceneInputs(TIMING), axes.SegueFrame())


def test_a_leader_and_goals_make_a_partner_request() -> None:
    goals = [authoring.Goal("here", 1, (0.5, 0.0, 0.0))]
    scene = authoring.SceneInputs(TIMING, goals=goals, leader="lead.bvh")
    req = authoring.scene_request(
        {}, {"kind": "control", "control": "motion"}, scene, axes.SegueFrame()
    ).request
    assert req["control"] == {"bvh": "lead.bvh"}
    assert req["bodies"] == [{"time_s": 0.0, "position": [0.5, -0.0]}]


def test_report_goals_are_read_from_constraint_errors() -> None:
    report = {"constraint_errors": {"body[0]": {"frame": 0, "position_cm": 1.5, "satisfied": True},
                                    "c1.body[2]": {"frame": 9, "position_cm": 40.0, "satisfied": False},
                                    "length": {"frames": 3}}}  # fmt: skip
    got = authoring.goal_errors(report)
    assert [(g["dancer"], g["index"], g["satisfied"]) for g in got] == [(0, 0, True), (1, 2, False)]


def test_glb_join_pads_chunks() -> None:
    out = gltf.join_glb({"asset": {"version": "2.0"}}, b"abc")
    assert len(out) % 4 == 0
    assert struct.unpack_from("<I", out, 8)[0] == len(out)


def test_pose_markers_label_a_clip_in_its_own_frames() -> None:
    markers = [authoring.Marker("walk", 10), authoring.Marker("run, !jump", 40), authoring.Marker("-", 70)]
    assert authoring.label_ranges(markers, 10, 99) == [
        {"label": "walk", "start": 0, "end": 30, "value": 1},
        {"label": "run", "start": 30, "end": 60, "value": 1},
        {"label": "jump", "start": 30, "end": 60, "value": -1},
    ]
    assert authoring.label_ranges([authoring.Marker("idle", 5)], 1, 20) == [
        {"label": "idle", "start": 4, "end": 20, "value": 1}
    ]
