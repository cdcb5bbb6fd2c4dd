"""Joint correspondence: every naming preset, spine chains of other lengths, the explicit map,
and the errors naming missing joints."""

from __future__ import annotations

import numpy as np
import pytest

from motion import MotionError
from motion.io import load_motion
from motion.retarget import correspond, detect_roles, retarget
from motion.retarget.names import REQUIRED, bare_name, pair_chains

from .characters import RENAMES, angle_deg, bone_directions, character, renamed_limbs, walk


@pytest.mark.parametrize("convention", sorted(RENAMES))
def test_each_preset_is_recognised_and_drives_the_limbs(convention: str) -> None:
    char = character(convention, scale=1.1)
    roles = detect_roles(char.skeleton)
    assert roles.preset == convention
    assert set(REQUIRED) <= set(roles.joints)
    src = walk(120)
    out = retarget(src, char, plant=False)
    assert out.skeleton is char.skeleton and out.units == char.units
    err = angle_deg(
        bone_directions(src, renamed_limbs(None)), bone_directions(out, renamed_limbs(convention))
    )
    assert err.max() < 0.5, f"{convention}: limbs off by up to {err.max():.2f} deg"


def test_daz_and_cmu_sources_are_recognised() -> None:
    assert detect_roles(walk(2).skeleton).preset == "cmu-daz"
    cmu = load_motion("sample:start-walk-stop").skeleton
    roles = detect_roles(cmu)
    assert roles.preset == "cmu" and cmu.names[roles.joints["LeftUpperArm"]] == "LeftShoulder"


def test_namespaces_are_ignored() -> None:
    assert bare_name("mixamorig:LeftUpLeg") == "LeftUpLeg"
    assert bare_name("mixamorig7:Hips") == "Hips"
    assert bare_name("thigh_l") == "thigh_l"


def test_spine_chains_of_other_lengths_pair_ends_and_middles() -> None:
    # CMU's torso has lowerback, Chest, Chest2 (lowerback at the hips); CMU-Daz has abdomen, chest
    cmu = load_motion("sample:start-walk-stop").slice(0, 1)
    corr = correspond(walk(2).skeleton, cmu.skeleton)
    names = {cmu.skeleton.names[t]: walk(2).skeleton.names[s] for t, s in corr.pairs.items()}
    assert names["lowerback"] == "abdomen" and names["Chest2"] == "chest"
    assert "Chest" not in names  # the middle joint keeps its rest rotation
    assert pair_chains([1, 2, 3, 4, 5], [7, 8, 9]) == {1: 7, 5: 9, 3: 8}
    assert pair_chains([1, 2], [7, 8, 9, 10]) == {1: 7, 2: 10}
    assert pair_chains([], [1]) == {}


def test_missing_feet_are_named() -> None:
    char = character("unreal")
    sk = char.skeleton
    names = tuple("ankle_x" if n == "foot_l" else n for n in sk.names)
    broken = type(sk)(names, sk.parents, sk.offsets, sk.channels, sk.end_site_parents, sk.end_site_offsets)
    with pytest.raises(MotionError, match=r"character has no joint for: left foot.*--map"):
        correspond(walk(2).skeleton, broken)
    # the explicit map names it, by source joint or by role
    for key in ("lFoot", "LeftFoot"):
        corr = correspond(walk(2).skeleton, broken, {key: "ankle_x"})
        assert corr.target_roles["LeftFoot"] == names.index("ankle_x")


def test_map_errors_name_the_problem() -> None:
    sk = walk(2).skeleton
    char = character("humanoid").skeleton
    with pytest.raises(MotionError, match="no joint named 'Nope'"):
        correspond(sk, char, {"lFoot": "Nope"})
    with pytest.raises(MotionError, match="neither a joint of the motion nor a role"):
        correspond(sk, char, {"Elbow?": "LeftFoot"})


def test_map_pairs_extra_joints() -> None:
    # a joint no preset knows (a finger) is driven when mapped, else it keeps its rest rotation
    src = walk(60)
    char = character("unreal")
    plain = retarget(src, char, plant=False)
    mapped = retarget(src, char, name_map={"lIndex2": "lIndex2"}, plant=False)
    j = char.skeleton.index("lIndex2")
    assert np.allclose(plain.rotations[:, j], char.rotations[0, j])  # unmapped: rest rotation
    assert not np.allclose(mapped.rotations[:, j], char.rotations[0, j])
