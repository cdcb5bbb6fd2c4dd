"""GLB exports for game engines: rest pose on the floor, in place, events, one skin per character,
units per target (issue 15). Re-animation uses the independent reader of :mod:`.test_glb`."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import motion
from motion import ExportError
from motion import rotations as rot
from motion.contacts import detect_contacts
from motion.export.characters import combine_characters, split_characters
from motion.export.events import (
    contact_events,
    contact_events_of,
    parse_kinds,
    result_events,
    sorted_events,
)
from motion.export.glb import glb_bytes
from motion.ground import ground_frames, to_ground_frame
from motion.io import save_motion
from motion.resample import resample
from motion.samples import sample_path

from .synthetic import walking_biped
from .test_glb import TOL_M, check_file, node_globals, read_glb

BANDAI = (
    Path(__file__).resolve().parents[3] / "shared/data/bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh"
)


def rest_heights(data: bytes) -> dict[str, float]:
    """Rest-pose height (m) of every skin joint and End Site node, the ground roots left out."""
    glb = read_glb(data)
    g = node_globals(glb, None)
    nodes = glb.gltf["nodes"]
    joints = {j for s in glb.gltf["skins"] for j in s["joints"]}
    marked = [
        i for i, n in enumerate(nodes) if (i in joints or n["name"].endswith("_end")) and "mesh" not in n
    ]
    return {nodes[i]["name"]: float(g[i, 1, 3]) for i in marked if not nodes[i]["name"].endswith("ground")}


def lying_down(m: motion.Motion) -> motion.Motion:
    """The same animation on a skeleton whose zero-rotation pose lies along +X (like Bandai-Namco
    files): offsets turned by R (-90 deg about Z), local rotations conjugated so every frame's
    global positions are unchanged."""
    r = rot.from_axis_angle(np.array([0.0, 0.0, 1.0]), -np.pi / 2)
    sk = m.skeleton
    turned = motion.Skeleton(
        sk.names,
        sk.parents,
        rot.rotate(r, sk.offsets),
        sk.channels,
        sk.end_site_parents,
        rot.rotate(r, sk.end_site_offsets),
    )
    q = rot.multiply(rot.multiply(r, m.rotations), rot.conjugate(r))
    q[:, 0] = rot.multiply(m.rotations[:, 0], rot.conjugate(r))
    return replace(m, skeleton=turned, rotations=q)


# -- rest pose -------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["walk", "salsa-leader-02", "start-walk-stop"])
def test_rest_pose_stands_on_the_floor(name: str) -> None:
    m = motion.read_bvh(sample_path(name)).slice(0, 40)
    data = glb_bytes(m)
    h = rest_heights(data)
    assert min(h.values()) == pytest.approx(0.0, abs=1e-6)  # the lowest point on the floor
    head = max(v for k, v in h.items() if "head" in k.lower())
    hips = next(v for k, v in h.items() if k.lower() in ("hip", "hips", "root"))
    assert 0.6 < hips < head - 0.2  # standing: hips at their height, head above them
    check_file(data, m, ground=True)  # the animation is unchanged


def test_rest_pose_of_a_skeleton_lying_down_is_a_standing_frame() -> None:
    m = walking_biped(frames=30)
    lying = lying_down(m)
    np.testing.assert_allclose(lying.global_positions(), m.global_positions(), atol=1e-9)
    data = glb_bytes(lying)
    h = rest_heights(data)
    assert min(h.values()) == pytest.approx(0.0, abs=1e-6)
    assert h["head"] > h["hips"] + 0.2 and h["lFoot"] < 0.2
    glb = check_file(data, lying, ground=True)  # skinning and re-animation still exact
    assert any("rotation" in n for n in glb.gltf["nodes"])  # the bind pose holds the standing rotations


@pytest.mark.skipif(not BANDAI.exists(), reason="../shared/data (Bandai-Namco) is not here")
def test_bandai_walk_stands_in_metres() -> None:
    m = motion.read_bvh(BANDAI)
    h = rest_heights(glb_bytes(m))
    assert min(h.values()) == pytest.approx(0.0, abs=1e-6)
    assert 1.3 < h["Head"] < 1.8 and 0.8 < h["Hips"] < 1.1


# -- in place --------------------------------------------------------------------------------------
def test_in_place_keeps_the_body_over_the_origin_and_root_motion_on_ground() -> None:
    m = motion.read_bvh(sample_path("walk")).slice(1, 90).to_units("m")
    glb = read_glb(glb_bytes(m, in_place=True))
    gltf = glb.gltf
    (skin,) = gltf["skins"]
    nodes = gltf["nodes"]
    origin, ground, hips = skin["joints"][:3]
    assert [nodes[j]["name"] for j in (origin, ground, hips)] == ["origin", "ground", "hip"]
    assert skin["skeleton"] == origin and nodes[origin]["children"][:2] == [ground, hips]  # one root
    assert hips not in nodes[ground].get("children", [])
    pos = m.global_positions()
    xz, yaw = ground_frames(m, pos)
    local = to_ground_frame(pos, xz, yaw)
    for f in (0, 40, 88):
        g = node_globals(glb, f)
        np.testing.assert_allclose(g[origin], np.eye(4), atol=1e-12)  # the origin never moves
        np.testing.assert_allclose(g[skin["joints"][2:], :3, 3], local[f], atol=TOL_M)
        np.testing.assert_allclose(g[ground, [0, 2], 3], xz[f], atol=TOL_M)  # root motion kept
    travel = np.linalg.norm(xz[-1] - xz[0])
    assert travel > 0.8  # the walk travels, the body stays
    assert np.abs(local[:, 0, [0, 2]]).max() < 0.2
    with pytest.raises(ExportError, match="ground root"):
        glb_bytes(m, in_place=True, ground_root=False)


# -- events ----------------------------------------------------------------------------------------
def test_contact_events_in_animation_extras() -> None:
    m = motion.read_bvh(sample_path("walk")).slice(1, 200)
    evs = contact_events(m)
    glb = read_glb(glb_bytes(m, events=evs))
    got = glb.gltf["animations"][0]["extras"]["events"]
    # 1.7 s of walk: right, left, right plants, one event each
    assert got == evs and [e["joint"] for e in sorted_events(got)] == ["rFoot", "lFoot", "rFoot"]
    joints, flags = detect_contacts(m)
    for e in got:  # each plant holds contact frames of the quality report's detector
        k = [m.skeleton.names[j] for j in joints].index(e["joint"])
        a = round(e["time_s"] * m.fps)
        assert flags[a : a + round(e["duration_s"] * m.fps), k].any()
    assert all(0 <= e["time_s"] <= m.duration_s for e in got)


def test_result_events_and_kinds() -> None:
    ann = {"music_beats_s": [0.5, 1.0, 99.0], "achieved_ranges": {"walk": [[0, 30]], "run": [[30, 45]]}}
    evs = result_events(ann, 30.0, 2.0)
    assert [e["type"] for e in evs].count("beat") == 2  # the beat past the end is left out
    labels = [e for e in evs if e["type"] == "label"]
    assert {(e["label"], e["time_s"], e["duration_s"]) for e in labels} == {
        ("walk", 0.0, 1.0),
        ("run", 1.0, 0.5),
    }
    assert parse_kinds("all") == ("contacts", "beats", "labels")
    assert parse_kinds("beats, contacts") == ("beats", "contacts")
    with pytest.raises(motion.MotionError, match="unknown event kind"):
        parse_kinds("footsteps")


def test_json_frames_carry_events(tmp_path: Path) -> None:
    m = walking_biped(frames=60)
    save_motion(m, tmp_path / "a.json", events=["contacts"])
    doc = json.loads((tmp_path / "a.json").read_text())
    assert doc["events"] == sorted_events(contact_events(m)) and doc["events"]
    with pytest.raises(ExportError, match="events"):
        save_motion(m, tmp_path / "a.bvh", events=["contacts"])
    with pytest.raises(ExportError, match="in-place"):
        save_motion(m, tmp_path / "a.bvh", in_place=True)


# -- several characters ----------------------------------------------------------------------------
def crowd(n: int) -> tuple[motion.Motion, list[motion.Motion]]:
    base = motion.read_bvh(sample_path("walk-05-01")).slice(0, 30)
    shift = np.array([100.0, 0.0, 0.0])
    people = [replace(base, root_positions=base.root_positions + k * shift) for k in range(n)]
    return combine_characters(people, [f"c{k}_" for k in range(n)]), people


def test_combined_motion_splits_back() -> None:
    combined, people = crowd(3)
    parts = split_characters(combined)
    assert parts is not None and len(parts) == 3
    for part, person in zip(parts, people, strict=True):
        assert part.skeleton.names == tuple(f"{part.skeleton.names[0][:3]}{n}" for n in person.skeleton.names)
        np.testing.assert_allclose(part.global_positions(), person.global_positions(), atol=1e-9)
    assert split_characters(people[0]) is None


def test_crowd_has_one_skin_per_character_and_grows_linearly() -> None:
    combined, people = crowd(3)
    data = glb_bytes(combined)
    glb = read_glb(data)
    gltf = glb.gltf
    skins = gltf["skins"]
    assert len(skins) == 3
    assert len({j for s in skins for j in s["joints"]}) == sum(len(s["joints"]) for s in skins)
    # each character bound where it stands in its first frame (Godot 3.2 merges equal skins): its
    # own bind matrices and vertex positions; the same body shares its other vertex attributes
    assert len({s["inverseBindMatrices"] for s in skins}) == 3
    prims = [m["primitives"][0] for m in gltf["meshes"]]
    assert len({p["attributes"]["POSITION"] for p in prims}) == 3
    for key in ("NORMAL", "JOINTS_0", "WEIGHTS_0"):
        assert len({p["attributes"][key] for p in prims}) == 1
    ibms = [glb.accessor(s["inverseBindMatrices"]) for s in skins]
    for ibm, person in zip(ibms, people, strict=True):
        root = np.linalg.inv(ibm[0])[:3, 3]
        np.testing.assert_allclose(root[[0, 2]], person.root_positions[0, [0, 2]] * 0.01, atol=1e-5)
    mesh_nodes = [n for n in gltf["nodes"] if "mesh" in n]
    assert sorted(n["skin"] for n in mesh_nodes) == [0, 1, 2]
    nodes = gltf["nodes"]
    for k, (skin, person) in enumerate(zip(skins, people, strict=True)):
        assert nodes[skin["joints"][0]]["name"] == f"c{k}_ground"
        names = [nodes[j]["name"] for j in skin["joints"][1:]]
        assert names == [f"c{k}_{n}" for n in person.skeleton.names]
        for f in (0, 29):
            g = node_globals(glb, f)
            np.testing.assert_allclose(
                g[skin["joints"][1:], :3, 3], person.global_positions()[f] * 0.01, atol=TOL_M
            )
    # each rig under its own plain node (one armature / Skeleton each), one animation each
    parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
    groups = [parent[s["joints"][0]] for s in skins]
    assert [nodes[g]["name"] for g in groups] == ["c0", "c1", "c2"]
    assert all(g in gltf["scenes"][0]["nodes"] and "mesh" not in nodes[g] for g in groups)
    anims = gltf["animations"]
    assert [a["name"] for a in anims] == [f"{combined.name or 'motion'}_c{k}" for k in range(3)]
    for anim, skin in zip(anims, skins, strict=True):
        assert {c["target"]["node"] for c in anim["channels"]} == set(skin["joints"])
    sizes = [len(glb_bytes(crowd(n)[0])) for n in (1, 2, 4)]
    per = (sizes[2] - sizes[1]) / 2
    assert per == pytest.approx(sizes[1] - sizes[0], rel=0.02)  # linear in the number of characters
    heights = rest_heights(data)
    assert min(heights.values()) == pytest.approx(0.0, abs=1e-6)


def test_characters_at_one_place_still_have_skins_of_their_own() -> None:
    base = motion.read_bvh(sample_path("walk-05-01")).slice(0, 30)
    glb = read_glb(glb_bytes(combine_characters([base, base, base], ["c0_", "c1_", "c2_"])))
    roots = [np.linalg.inv(glb.accessor(s["inverseBindMatrices"])[0])[:3, 3] for s in glb.gltf["skins"]]
    assert np.diff(np.array(roots)[:, 0]) == pytest.approx([0.001, 0.001], abs=2e-6)  # 1 mm apart


def test_crowd_contact_events_name_their_character() -> None:
    combined, people = crowd(2)
    evs = contact_events_of(combined)
    assert {e["character"] for e in evs} == {"c0", "c1"}
    assert [e for e in evs if e["character"] == "c0"] == [
        dict(e, character="c0", joint="c0_" + e["joint"]) for e in contact_events(people[0])
    ]


# -- units per target ------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("target", "units"), [("gltf", "m"), ("godot", "m"), ("unity", "m"), ("unreal", "cm")]
)
def test_every_format_follows_the_target_units(tmp_path: Path, target: str, units: str) -> None:
    m = motion.read_bvh(sample_path("walk")).slice(1, 20)  # a file in centimetres
    assert m.units == "cm"
    save_motion(m, tmp_path / "a.bvh", target=target)
    back = motion.read_bvh(tmp_path / "a.bvh", units=units)
    height = np.ptp(back.global_positions()[0], axis=0).max() * back.metres_per_unit
    assert 1.2 < height < 2.0
    save_motion(m, tmp_path / "a.json", target=target)
    assert json.loads((tmp_path / "a.json").read_text())["convention"]["units"] == units
    save_motion(m, tmp_path / "b.bvh", target=target, units="mm")  # the override
    back_mm = motion.read_bvh(tmp_path / "b.bvh", units="mm")
    np.testing.assert_allclose(np.ptp(back_mm.global_positions()[0], axis=0).max() / 1000, height, rtol=1e-5)
    with pytest.raises(ExportError, match="metres"):
        save_motion(m, tmp_path / "a.glb", target=target, units="cm")


def test_channels_that_never_change_get_one_key() -> None:
    m = motion.read_bvh(sample_path("salsa-leader-02")).slice(0, 60)
    data = glb_bytes(m)
    glb = check_file(data, m, ground=True)  # re-animates exactly with the one-key channels
    anim = glb.gltf["animations"][0]
    nodes = glb.gltf["nodes"]
    one_key = {
        nodes[c["target"]["node"]]["name"]
        for c in anim["channels"]
        if glb.gltf["accessors"][anim["samplers"][c["sampler"]]["output"]]["count"] == 1
    }
    assert {"lIndex1", "rPinky2"} <= one_key and "hip" not in one_key and "lThigh" not in one_key


@pytest.mark.skipif(not BANDAI.exists(), reason="../shared/data (Bandai-Namco) is not here")
def test_bandai_in_place_under_a_static_file_root() -> None:
    """Bandai-Namco files have a static ``joint_Root`` above the hips: in place still holds."""
    m = motion.read_bvh(BANDAI).slice(0, 60)
    glb = read_glb(glb_bytes(m, in_place=True))
    (skin,) = glb.gltf["skins"]
    pos = m.global_positions() * m.metres_per_unit
    xz, yaw = ground_frames(m, pos)
    local = to_ground_frame(pos, xz, yaw)
    for f in (0, 59):
        g = node_globals(glb, f)
        np.testing.assert_allclose(g[skin["joints"][2:], :3, 3], local[f], atol=TOL_M)


def test_crowd_events_reach_each_dancer_and_the_scene() -> None:
    combined, _ = crowd(2)
    evs = [*contact_events_of(combined), {"type": "beat", "index": 0, "time_s": 0.1}]
    gltf = read_glb(glb_bytes(combined, events=evs)).gltf
    assert gltf["scenes"][0]["extras"]["events"] == evs
    nodes = gltf["nodes"]
    for k, anim in enumerate(gltf["animations"]):
        mine = [e for e in evs if e.get("character", f"c{k}") == f"c{k}"]
        assert anim["extras"]["events"] == mine and any(e["type"] == "contact" for e in mine)
        group = next(n for n in nodes if n.get("name") == f"c{k}")
        assert group["extras"]["events"] == mine  # Blender: the armature's custom property


@pytest.mark.parametrize("name", ["walk", "walk-05-01", "run-09-01"])
def test_contact_count_does_not_depend_on_the_frame_rate(name: str) -> None:
    """One plant is one event: the issue's sample:walk gave 12 contacts at 120 fps, 5 at 30."""
    m = motion.read_bvh(sample_path(name))
    counts = {fps: len(contact_events(resample(m, fps))) for fps in (24.0, 30.0, 60.0, 120.0)}
    assert len(set(counts.values())) == 1 and counts[30.0] > 0, counts


def test_contact_count_of_a_dance_barely_depends_on_the_frame_rate() -> None:
    m = motion.read_bvh(sample_path("salsa-follower-02"))
    counts = [len(contact_events(resample(m, fps))) for fps in (24.0, 30.0, 60.0, 120.0)]
    assert max(counts) - min(counts) <= 0.05 * max(counts), counts


def test_one_contact_per_plant_whatever_the_names() -> None:
    """A foot's ankle and toe planting together are one plant: under Mixamo names (``LeftFoot``,
    ``LeftToeBase``, both found by name) a walk gave two events per plant, 10 where Unreal names
    (``ball_l`` is not named like a toe) gave 5."""
    from motion.refpose import without_reference_lead
    from motion.retarget import retarget
    from motion.retarget.character import gltf_character

    from .retarget.gltf_rig import unreal_character_glb
    from .retarget.namings import renamed_glb

    walk, _ = without_reference_lead(motion.io.load_motion("sample:walk"))
    events = {}
    for naming in ("unreal", "mixamo"):
        out = retarget(walk, gltf_character(renamed_glb(unreal_character_glb(), naming)))
        events[naming] = contact_events(out)
    assert len(events["unreal"]) == len(events["mixamo"]) == 5
    assert {e["joint"] for e in events["mixamo"]} == {"mixamorig:LeftFoot", "mixamorig:RightFoot"}
