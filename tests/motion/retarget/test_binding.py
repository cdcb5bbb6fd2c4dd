"""The per-frame binding (motion/retarget/binding.py): what a viewer applies to streamed frames is the
retargeting's own transfer, measured once."""

from __future__ import annotations

import json

import numpy as np
import pytest

from motion import MotionError, Skeleton
from motion.io import load_motion
from motion.retarget import retarget
from motion.retarget.binding import apply_binding, bind, own_binding, rest_motion
from motion.retarget.character import gltf_character
from tests.motion.retarget.characters import character
from tests.motion.retarget.gltf_rig import unreal_character_glb


def _metres(name: str):  # type: ignore[no-untyped-def]
    m = load_motion(name)
    return m.scaled(m.metres_per_unit, "m")


@pytest.fixture(scope="module")
def hero():  # type: ignore[no-untyped-def]
    return gltf_character(unreal_character_glb())


@pytest.mark.parametrize("sample", ["walk", "salsa-leader", "run-09-04"])
def test_bound_to_the_whole_motion_it_is_the_retargeting_without_leg_ik(sample: str, hero) -> None:  # type: ignore[no-untyped-def]
    """With the motion itself as the example, applying the binding frame by frame gives exactly
    what retarget() gives without its foot planting: the same transfer, hip path and feet."""
    m = _metres(f"sample:{sample}")
    b = bind(m.skeleton, hero, example=m)
    got = apply_binding(b, m, hero).global_positions()
    want = retarget(m, hero, feet="free").global_positions()
    assert np.abs(got - want).max() < 1e-6


def test_bound_to_a_few_frames_it_stays_within_centimetres(hero) -> None:  # type: ignore[no-untyped-def]
    """A live session's first seconds as the example: the rest of the dance follows within a few cm."""
    m = _metres("sample:salsa-leader")
    b = bind(m.skeleton, hero, example=m.slice(0, 120))
    err = np.linalg.norm(
        apply_binding(b, m, hero).global_positions() - retarget(m, hero, feet="free").global_positions(),
        axis=-1,
    )
    assert np.percentile(err, 95) < 0.04 and err.max() < 0.06


def test_rest_only_binding_turns_limbs_as_the_transfer_does(hero) -> None:  # type: ignore[no-untyped-def]
    """Without an example, limbs point as the transfer makes them (positions relative to the hips
    agree except the feet, which the transfer lays flat where the motion plants them), and the
    hips keep their height above the floor within a few centimetres."""
    m = _metres("sample:walk")
    b = bind(m.skeleton, hero)
    got = apply_binding(b, m, hero).global_positions()
    want = retarget(m, hero, feet="free").global_positions()
    names = hero.skeleton.names
    feet = [names.index(n) for n in ("foot_l", "foot_r", "ball_l", "ball_r")]
    body = [j for j in range(len(names)) if j not in feet and j != 0]
    rel = (got - got[:, [b.hips]]) - (want - want[:, [b.hips]])
    assert np.abs(rel[:, body]).max() < 1e-6
    assert np.abs(got[:, b.hips, 1] - want[:, b.hips, 1]).max() < 0.06


@pytest.mark.parametrize("turned", [False, True])
def test_a_character_on_the_sources_own_skeleton_moves_as_the_motion(turned: bool) -> None:
    """The mannequin's case (own_binding): a character made on the source's own skeleton follows
    it exactly, whether its file stores the joints in their rest orientation or turned (a mesh
    made in the first frame's pose)."""
    m = _metres("sample:walk")
    rest = m.slice(0, 1)
    char = rest
    if turned:  # the same joints where the rest has them, stored unrotated (identity orientations)
        pos = rest.global_positions()[0]
        offsets = pos - np.where(m.skeleton.parents[:, None] >= 0, pos[m.skeleton.parents], 0.0)
        unturned = Skeleton(m.skeleton.names, m.skeleton.parents, offsets, m.skeleton.channels)
        char = rest_motion(unturned, "m")
    b = own_binding(rest, char)
    got = apply_binding(b, m, char).global_positions()
    assert np.abs(got - m.global_positions()[:, : m.skeleton.num_joints]).max() < 1e-6
    assert turned != np.allclose(b.offsets, [0, 0, 0, 1])
    with pytest.raises(MotionError, match="not on the source's skeleton"):
        own_binding(rest, gltf_character(unreal_character_glb()))


def test_json_names_joints_and_round_trips_offsets(hero) -> None:  # type: ignore[no-untyped-def]
    m = _metres("sample:walk")
    b = bind(m.skeleton, hero)
    doc = json.loads(json.dumps(b.to_json()))
    assert doc["source"] == list(m.skeleton.names) and doc["target"] == list(hero.skeleton.names)
    assert doc["hips"]["joint"] == "pelvis" and doc["hips"]["source"] == "hip"
    pairs = {j["joint"]: j["source"] for j in doc["joints"]}
    assert pairs["thigh_l"] == "lThigh" and pairs["hand_r"] == "rHand" and "ik_foot_root" not in pairs
    offsets = np.array([j["offset"] for j in doc["joints"]])
    assert np.allclose(np.linalg.norm(offsets, axis=1), 1, atol=1e-6)


def test_skeletons_that_do_not_correspond_are_refused(hero) -> None:  # type: ignore[no-untyped-def]
    m = _metres("sample:walk")
    legless = character("mixamo")
    with pytest.raises(MotionError, match="the example frames are not on the source skeleton"):
        bind(m.skeleton, hero, example=legless)
    arm = rest_motion(
        m.skeleton.__class__(
            ("a", "b"),
            np.array([-1, 0]),
            np.zeros((2, 3)),
            (
                ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),
                ("Zrotation", "Yrotation", "Xrotation"),
            ),
        )
    )
    with pytest.raises(MotionError, match="no joint for"):
        bind(arm.skeleton, hero)
    with pytest.raises(MotionError, match="other skeletons"):
        apply_binding(bind(m.skeleton, hero), legless, hero)
