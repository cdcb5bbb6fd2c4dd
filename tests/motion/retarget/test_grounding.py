"""The character's soles (motion.retarget.sole) and the passes that keep them on its floor
(motion.retarget.grounding): what each mode does, and the pieces each pass is made of."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from motion import MotionError
from motion import rotations as rot
from motion.contacts import detect_contacts
from motion.footskate import move_feet
from motion.io import load_motion
from motion.refpose import without_reference_lead
from motion.retarget import correspond, retarget
from motion.retarget.character import gltf_character
from motion.retarget.grounding import (
    lift_angles,
    plant_weights,
    reach_angles,
    upper_envelope,
)
from motion.retarget.legik import character_soles, feet_on_floor, foot_groups_of
from motion.retarget.sole import bone_soles, mesh_soles, soles_floor
from motion.skinning import read_skinned_mesh, skin_motion

from .characters import character
from .namings import game_rig, mannequin_character


@pytest.fixture(scope="module")
def walk() -> object:
    return without_reference_lead(load_motion("sample:walk"))[0]


@pytest.fixture(scope="module")
def hero() -> bytes:
    return mannequin_character("unreal")


def test_upper_envelope_is_the_smallest_slow_function_above() -> None:
    x = np.array([0.0, 0.0, 5.0, 0.0, 0.0, 0.0, -3.0, 0.0])
    e = upper_envelope(x, 2.0)
    np.testing.assert_allclose(e, [1.0, 3.0, 5.0, 3.0, 1.0, 0.0, -2.0, 0.0])
    assert np.all(e >= x) and np.abs(np.diff(e)).max() <= 2.0 + 1e-12


def test_plant_weights_fade_over_the_blend() -> None:
    flags = np.zeros(20, dtype=bool)
    flags[8:12] = True
    w = plant_weights(flags, 3)
    assert np.all(w[8:12] == 1.0) and w[0] == 0.0 and w[-1] == 0.0
    assert 0 < w[6] < w[7] < 1.0 and np.all(np.diff(w[:9]) >= 0)


def test_lift_and_reach_angles() -> None:
    pivot = np.array([[0.0, 0.02, 0.0]])
    axis = np.array([[-1.0, 0.0, 0.0]])  # cross(forward +Z, up): a positive turn lifts points ahead
    tip = np.array([[[0.0, -0.03, 0.05]]])  # 3 cm under the floor, 5 cm ahead of the ball
    theta = lift_angles(tip, pivot, axis, 0.0)[0]
    turned_y = 0.02 + (-0.05) * np.cos(theta) + 0.05 * np.sin(theta)
    assert turned_y == pytest.approx(0.0, abs=1e-9)  # just onto the floor
    assert lift_angles(tip + np.array([0.0, 0.2, 0.0]), pivot, axis, 0.0)[0] == 0.0  # above: no turn
    high = np.array([[[0.0, 0.05, 0.05]]])
    phi = reach_angles(high, pivot, -axis, 0.0)[0]  # turning it down onto the floor
    assert 0.02 + 0.03 * np.cos(phi) - 0.05 * np.sin(phi) == pytest.approx(0.0, abs=1e-9)


def test_mesh_soles_are_the_lowest_foot_vertices(hero: bytes) -> None:
    char = gltf_character(hero)
    mesh = read_skinned_mesh(hero)
    assert mesh is not None
    roles = correspond(load_motion("sample:walk").skeleton, char.skeleton).target_roles
    soles = mesh_soles(mesh, char, roles)
    floor = float(skin_motion(mesh, char)[0][:, 1].min())
    assert soles_floor(soles) == pytest.approx(floor, abs=1e-9)  # the mesh's lowest vertex
    pos, grot = char.fk()
    for s in soles:
        np.testing.assert_allclose(s.positions(pos, grot)[0], s.rest, atol=1e-9)
        assert s.on_toe.any() and (~s.on_toe).any()  # a heel part and a toe part
        length = np.ptp(s.rest[:, 2])
        assert length > 0.2  # heel to toe tip: the mannequin's foot, not its ankle joint


def test_bone_soles_stand_under_each_foot() -> None:
    char = character("unreal")  # CMU-Daz bones: no toe joint, an End Site at the toe tip
    roles = correspond(load_motion("sample:walk").skeleton, char.skeleton).target_roles
    soles = bone_soles(char, roles)
    pos = char.global_positions()[0]
    for s in soles:
        assert s.toe == -1 and not s.on_toe.any() and s.size == 6
        assert s.rest[:, 1].max() <= pos[s.ankle, 1]  # under the ankle
        assert np.ptp(s.rest[:, 1]) == 0.0  # flat in the rest pose


def test_lock_grounding_and_free(walk: object, hero: bytes) -> None:
    char = gltf_character(hero)
    mesh = read_skinned_mesh(hero)
    outs = {feet: retarget(walk, char, feet=feet, mesh=mesh) for feet in ("lock", "grounding", "free")}
    roles = correspond(walk.skeleton, char.skeleton).target_roles  # type: ignore[attr-defined]
    soles = character_soles(char, roles, mesh)
    floor = soles_floor(soles)
    groups = foot_groups_of(roles)

    def lowest(out: object) -> np.ndarray:
        pos, grot = out.fk()  # type: ignore[attr-defined]
        return np.min([s.positions(pos, grot)[:, :, 1].min(axis=1) for s in soles], axis=0) - floor

    def slide(out: object) -> float:  # planted ankles' floor speed, m/s (the report's contacts)
        ankles = np.array([g[0] for g in groups])
        pos = out.global_positions()  # type: ignore[attr-defined]
        _, flags = detect_contacts(out, ankles, positions=pos)  # type: ignore[arg-type]
        v = np.linalg.norm(np.diff(pos[:, ankles][:, :, [0, 2]], axis=0), axis=-1) * 120.0
        return float(v[flags[1:] & flags[:-1]].mean())

    assert lowest(outs["free"]).min() < -0.05  # the transfer alone sinks the soles (toes, heels)
    for feet in ("lock", "grounding"):
        assert lowest(outs[feet]).min() > -1e-3
    assert slide(outs["lock"]) < 0.5 * slide(outs["grounding"])  # lock holds planted feet
    with pytest.raises(MotionError, match="feet 'stomp'"):
        retarget(walk, char, feet="stomp")


def test_move_feet_keeps_the_ankles_place_on_the_floor(walk: object) -> None:
    char = character("unreal")
    out = retarget(walk, char, feet="free")
    roles = correspond(walk.skeleton, char.skeleton).target_roles  # type: ignore[attr-defined]
    ankles = np.array([roles["LeftFoot"], roles["RightFoot"]])
    shifts = np.zeros((out.num_frames, 2, 3))
    shifts[:, :, 1] = -40.0  # 40 cm down: out of reach in most frames (centimetre rig)
    moved = move_feet(out, ankles, shifts)
    a, b = out.global_positions()[:, ankles], moved.global_positions()[:, ankles]
    np.testing.assert_allclose(b[..., [0, 2]], a[..., [0, 2]], atol=1e-6)  # the floor position kept
    assert np.all(b[..., 1] <= a[..., 1] + 1e-6) and (b[..., 1] < a[..., 1] - 1.0).any()


def test_a_motions_own_feet_on_its_floor(walk: object) -> None:
    for mode in ("lock", "grounding"):
        out = feet_on_floor(walk, mode)  # type: ignore[arg-type]
        assert out.skeleton is walk.skeleton  # type: ignore[attr-defined]
    assert feet_on_floor(walk, "free") is walk  # type: ignore[arg-type]
    rig = game_rig()
    renamed = type(rig.skeleton)(
        tuple(f"j{k}" for k in range(rig.num_joints)),
        rig.skeleton.parents,
        rig.skeleton.offsets,
        rig.skeleton.channels,
    )
    nameless = type(rig)(renamed, rig.root_positions.repeat(2, 0), rig.rotations.repeat(2, 0), 30.0)
    with pytest.raises(MotionError, match="no joint found"):
        feet_on_floor(nameless, "lock")


def test_a_foot_turned_over_is_lowest_where_its_mesh_is(hero: bytes) -> None:
    """A source may turn a foot over (a flick pointing the sole up): the top of the foot is then
    its lowest part, and the sole's points must hold it (before, only vertices near the rest
    floor were: the held-out character's mesh went 2.9 cm under the floor on the rhythm dance),
    and the points kept above the floor hold the vertices the foot shares with the shin (before,
    a heel vertex weighted 0.4995 to the foot went 1.4 cm under it)."""
    char = gltf_character(hero)
    mesh = read_skinned_mesh(hero)
    assert mesh is not None
    roles = correspond(load_motion("sample:walk").skeleton, char.skeleton).target_roles
    m = mesh.reindexed(char.skeleton.names)
    # automatic weights share the heel with the shin: half the heel's vertices 0.45 foot, 0.55 shin
    joints, weights = np.array(m.joints, copy=True), np.array(m.weights, copy=True)
    for side in ("Left", "Right"):
        ankle, shin = roles[f"{side}Foot"], roles[f"{side}LowerLeg"]
        rest_y = skin_motion(m, char)[0][:, 1]
        heel = np.flatnonzero((joints[:, 0] == ankle) & (weights[:, 0] == 1.0) & (rest_y < np.median(rest_y)))
        heel = heel[::2]
        joints[heel, 1], weights[heel, 0], weights[heel, 1] = shin, 0.45, 0.55
    m = replace(m, joints=joints, weights=weights)
    soles = mesh_soles(m, char, roles)
    for turn in ((180.0, 0.0, 0.0), (0.0, 0.0, 180.0), (115.0, 0.0, 0.0), (0.0, 0.0, -125.0)):
        for s in soles:
            q = np.array(char.rotations, copy=True)
            q[0, s.ankle] = rot.multiply(q[0, s.ankle], rot.from_euler("XYZ", np.array([turn]))[0])
            turned = replace(char, rotations=q)
            pos, grot = turned.fk()
            verts = skin_motion(m, turned)[0]
            foot = np.zeros(char.skeleton.num_joints, dtype=bool)
            for j in range(char.skeleton.num_joints):  # the foot's subtree
                k = j
                while k >= 0 and k != s.ankle:
                    k = int(char.skeleton.parents[k])
                foot[j] = k == s.ankle
            share = np.where(foot[m.joints], m.weights, 0.0).sum(axis=1)
            lowest = float(verts[share >= 0.5, 1].min())
            assert s.positions(pos, grot)[0][:, 1].min() == pytest.approx(lowest, abs=2e-3), (s.side, turn)
            # and every vertex moving at least a quarter with the foot (a heel shared with the shin)
            assert s.guard is not None
            lowest = float(verts[share >= 0.25, 1].min())
            assert s.around(pos, grot)[0][:, 1].min() == pytest.approx(lowest, abs=2e-3), (s.side, turn)
