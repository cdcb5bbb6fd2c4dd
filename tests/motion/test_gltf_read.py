"""Reading a glTF animation as a motion (:mod:`motion.gltf`): Segue's own GLBs give back their
frames, several animations are listed and picked, node transforms above the skin are applied, and
the samplers' interpolations are evaluated as glTF defines them.

Expected values come from the BVH the GLB was written from, or from closed forms (Hermite
polynomials, a rotation and scale applied by hand), never from the reader under test."""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest

from motion import MotionError
from motion import rotations as rot
from motion.export.characters import combine_characters
from motion.export.glb import glb_bytes
from motion.export.gltf_doc import read_gltf
from motion.gltf import gltf_animations, parse_gltf
from motion.io import load_motion, parse_motion
from motion.samples import SAMPLES
from tests.glb_writer import glb

MOTION_SAMPLES = [name for name, file in SAMPLES.items() if ".bvh" in file]


@pytest.mark.parametrize("sample", MOTION_SAMPLES)
def test_every_bundled_sample_round_trips_through_its_glb(sample: str) -> None:
    # issue 39: convert BVH -> GLB -> BVH gives the same joint positions within 1e-4 m
    bvh = load_motion(f"sample:{sample}").to_units("m")
    back = parse_gltf(glb_bytes(bvh))
    assert back.skeleton.names == bvh.skeleton.names  # Segue's ground root folded back
    np.testing.assert_array_equal(back.skeleton.parents, bvh.skeleton.parents)
    np.testing.assert_array_equal(back.skeleton.end_site_parents, bvh.skeleton.end_site_parents)
    assert (back.num_frames, back.fps, back.units) == (bvh.num_frames, bvh.fps, "m")
    pos_a, rot_a = bvh.fk()
    pos_b, rot_b = back.fk()
    assert np.abs(pos_b - pos_a).max() < 1e-4
    assert np.abs(back.end_site_positions(pos_b, rot_b) - bvh.end_site_positions(pos_a, rot_a)).max() < 1e-4
    assert float(np.degrees(rot.angle_between(rot_a, rot_b)).max()) < 0.01


def test_an_in_place_glb_is_put_back_on_its_path() -> None:
    bvh = load_motion("sample:walk-05-01").to_units("m")
    back = parse_gltf(glb_bytes(bvh, in_place=True))
    assert back.skeleton.names == bvh.skeleton.names
    assert np.abs(back.global_positions() - bvh.global_positions()).max() < 1e-4


def _two_characters() -> tuple[bytes, list[np.ndarray]]:
    walk = load_motion("sample:walk-05-01").to_units("m").slice(0, 30)
    run = load_motion("sample:run-09-01").to_units("m").slice(0, 30)
    crowd = combine_characters([walk, run], ["c0_", "c1_"])
    return glb_bytes(crowd), [walk.global_positions(), run.global_positions()]


def test_every_animation_is_listed_and_read_by_name_or_index() -> None:
    data, expected = _two_characters()
    anims = gltf_animations(data)
    assert [(a.index, a.frames, a.fps, a.skin) for a in anims] == [(0, 30, 30.0, 0), (1, 30, 30.0, 1)]
    for pick in (anims[1].name, 1, "1"):
        motion = parse_gltf(data, animation=pick)
        assert motion.name == anims[1].name
        assert np.abs(motion.global_positions() - expected[1]).max() < 1e-4
    assert np.abs(parse_gltf(data).global_positions() - expected[0]).max() < 1e-4  # the first by default
    with pytest.raises(MotionError, match=r"no animation named 'dance'; the file has 0: '.*', 1: '.*'"):
        parse_gltf(data, animation="dance")
    with pytest.raises(MotionError, match="no animation 5: the file has 2"):
        parse_gltf(data, animation=5)


def test_node_transforms_above_the_skin_are_applied() -> None:
    # an "Armature" node turning the rig Z-up and scaling it by 2, as DCC exports do
    bvh = load_motion("sample:run-09-02").to_units("m")
    doc, binary = read_gltf(glb_bytes(bvh))
    turn = rot.from_axis_angle(np.array([1.0, 0.0, 0.0]), -np.pi / 2)
    doc["nodes"].append(
        {"name": "Armature", "rotation": turn.tolist(), "scale": [2.0, 2.0, 2.0], "children": [0]}
    )
    scene = doc["scenes"][0]["nodes"]
    scene[scene.index(0)] = len(doc["nodes"]) - 1
    motion = parse_gltf(glb(doc, bytes(binary)))
    expected = 2.0 * rot.rotate(turn, bvh.global_positions())
    assert np.abs(motion.global_positions() - expected).max() < 1e-4


def _tiny_gltf(interpolation: str, times: list[float], values: np.ndarray) -> bytes:
    """A .gltf (data URI buffer) with a two-joint skin whose child translation is animated."""
    t = np.asarray(times, dtype=np.float32)
    v = np.asarray(values, dtype=np.float32)
    raw = t.tobytes() + v.tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {"name": "root", "children": [1]},
            {"name": "tip", "translation": [0.0, 1.0, 0.0], "children": [2]},
            {"name": "tip_end", "translation": [0.0, 0.5, 0.0]},
        ],
        "skins": [{"joints": [0, 1]}],
        "buffers": [
            {
                "byteLength": len(raw),
                "uri": "data:application/octet-stream;base64," + base64.b64encode(raw).decode(),
            }
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": t.nbytes},
            {"buffer": 0, "byteOffset": t.nbytes, "byteLength": v.nbytes},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": len(t),
                "type": "SCALAR",
                "min": [float(t[0])],
                "max": [float(t[-1])],
            },
            {"bufferView": 1, "componentType": 5126, "count": len(v), "type": "VEC3"},
        ],
        "animations": [
            {
                "name": "move",
                "samplers": [{"input": 0, "output": 1, "interpolation": interpolation}],
                "channels": [{"sampler": 0, "target": {"node": 1, "path": "translation"}}],
            }
        ],
    }
    return json.dumps(doc).encode()


def test_cubic_spline_step_and_linear_samplers() -> None:
    # keys at 0 s and 1 s; the animation is read at its densest sampler's rate (1 fps): 2 frames;
    # 10 keys at 0.1 s make it 10 fps, so the spline is evaluated between keys
    times = [0.0, 1.0]
    a, b = np.array([0.0, 1.0, 0.0]), np.array([1.0, 1.0, 0.0])
    out_a, in_b = np.array([3.0, 0.0, 0.0]), np.array([-2.0, 0.0, 0.0])  # tangents (per second)
    spline = np.stack([np.zeros(3), a, out_a, in_b, b, np.zeros(3)])  # in, value, out per key
    dense_times = list(np.round(np.arange(11) * 0.1, 6))
    dense = np.stack([a + (b - a) * t for t in dense_times])
    linear = parse_gltf(_tiny_gltf("LINEAR", dense_times, dense))
    assert linear.num_frames == 11 and linear.fps == 10.0
    # the cubic spline over the same 10 fps grid (a second sampler sets the rate)
    doc = json.loads(_tiny_gltf("CUBICSPLINE", times, spline))
    dense_doc = json.loads(_tiny_gltf("LINEAR", dense_times, dense))
    raw = base64.b64decode(doc["buffers"][0]["uri"].split(",")[1])
    raw2 = base64.b64decode(dense_doc["buffers"][0]["uri"].split(",")[1])
    merged = raw + raw2
    doc["buffers"][0] = {
        "byteLength": len(merged),
        "uri": "data:;base64," + base64.b64encode(merged).decode(),
    }
    doc["bufferViews"] += [
        {"buffer": 0, "byteOffset": len(raw) + v["byteOffset"], "byteLength": v["byteLength"]}
        for v in dense_doc["bufferViews"]
    ]
    doc["accessors"] += [{**acc, "bufferView": acc["bufferView"] + 2} for acc in dense_doc["accessors"]]
    doc["animations"][0]["samplers"].append({"input": 2, "output": 3, "interpolation": "STEP"})
    doc["animations"][0]["channels"].append({"sampler": 1, "target": {"node": 0, "path": "translation"}})
    motion = parse_gltf(json.dumps(doc).encode())
    u = np.arange(11) / 10.0
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    expected_tip = h00[:, None] * a + h10[:, None] * out_a + h01[:, None] * b + h11[:, None] * in_b
    root = motion.root_positions
    np.testing.assert_allclose(root, dense, atol=1e-6)  # STEP on keys at every frame: the keys
    tip = motion.global_positions()[:, 1] - root
    np.testing.assert_allclose(tip, expected_tip, atol=1e-6)
    assert motion.skeleton.end_site_offsets.tolist() == [[0.0, 0.5, 0.0]]


def test_files_that_are_not_motions_say_why() -> None:
    data, _ = _two_characters()
    doc, binary = read_gltf(data)
    without = {k: v for k, v in doc.items() if k != "animations"}
    with pytest.raises(MotionError, match="has no animation"):
        parse_gltf(glb(without, bytes(binary)))
    unskinned = {k: v for k, v in doc.items() if k != "skins"}
    with pytest.raises(MotionError, match="no skin"):
        parse_gltf(glb(unskinned, bytes(binary)))
    with pytest.raises(MotionError, match="a glTF file is in metres"):
        parse_motion(data, units="cm")
    with pytest.raises(MotionError, match="'animation' is for glTF files"):
        parse_motion(b"HIERARCHY\n", animation=0)
    with pytest.raises(MotionError, match="over the 10 joint-frame limit"):
        parse_gltf(data, max_joint_frames=10)
