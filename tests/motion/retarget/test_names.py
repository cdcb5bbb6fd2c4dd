"""Joint correspondence: every naming preset, spine chains of other lengths, the explicit map,
and the errors naming missing joints."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from motion import Motion, MotionError, Skeleton
from motion import rotations as rot
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
    out = retarget(src, char, feet="free")
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
    plain = retarget(src, char, feet="free")
    mapped = retarget(src, char, name_map={"lIndex2": "lIndex2"}, feet="free")
    j = char.skeleton.index("lIndex2")
    assert np.allclose(plain.rotations[:, j], char.rotations[0, j])  # unmapped: rest rotation
    assert not np.allclose(mapped.rotations[:, j], char.rotations[0, j])


def _longer_spine(char: Motion, chest: str, extra: tuple[str, ...]) -> Motion:
    """``char`` with joints ``extra`` inserted above ``chest`` (an Unreal 5 spine of 5 joints): the
    chest's children hang from the last one, the bone from the chest to them is split evenly."""
    sk = char.skeleton
    c = sk.index(chest)
    kids = sk.children(c)
    step = np.mean(sk.offsets[kids], axis=0) / (len(extra) + 1)
    names = list(sk.names) + list(extra)
    parents = list(sk.parents) + [c + 0] + [sk.num_joints + k for k in range(len(extra) - 1)]
    offsets = np.vstack([sk.offsets, np.tile(step, (len(extra), 1))])
    for k in kids:
        parents[k] = len(names) - 1
        offsets[k] = sk.offsets[k] - len(extra) * step
    # parents must precede children: reorder so the new joints come right after the chest
    order = list(range(c + 1)) + list(range(sk.num_joints, len(names))) + list(range(c + 1, sk.num_joints))
    where = {old: new for new, old in enumerate(order)}
    skeleton = Skeleton(
        tuple(names[o] for o in order),
        np.array([-1 if parents[o] < 0 else where[parents[o]] for o in order]),
        offsets[order],
        tuple(sk.channels[o] if o < sk.num_joints else sk.channels[c] for o in order),
        np.array([where[int(p)] for p in sk.end_site_parents]),
        sk.end_site_offsets,
    )
    rotations = np.concatenate([char.rotations, np.tile(rot.IDENTITY, (1, len(extra), 1))], axis=1)[:, order]
    return replace(char, skeleton=skeleton, rotations=rotations)


def test_a_longer_spine_pairs_its_ends_and_keeps_the_rest() -> None:
    char = _longer_spine(character("unreal"), "spine_02", ("spine_03", "spine_04", "spine_05"))
    src = walk(120)
    corr = correspond(src.skeleton, char.skeleton)
    named = {char.skeleton.names[t]: src.skeleton.names[s] for t, s in corr.pairs.items()}
    assert named["spine_01"] == "abdomen" and named["spine_05"] == "chest"
    assert not {"spine_02", "spine_03", "spine_04"} & set(named)
    out = retarget(src, char, feet="free")
    err = angle_deg(bone_directions(src, renamed_limbs(None)), bone_directions(out, renamed_limbs("unreal")))
    assert err.max() < 0.5
    # the shoulders face where the source's do: the clavicle-to-clavicle axis follows the source's
    axis_s = bone_directions(src, (("rCollar", "lCollar"),))
    axis_o = bone_directions(out, (("clavicle_r", "clavicle_l"),))
    assert angle_deg(axis_s, axis_o).max() < 1.0


def test_a_cgspeed_cmu_file_is_named_cmu_not_mixamo() -> None:
    # Regression (issue 39): B. Hahne's CMU conversion shares Mixamo's limb names, and retarget's
    # summary called a CMU file "mixamo -> ...".
    from pathlib import Path

    from motion.io import load_motion

    corpus = Path(__file__).resolve().parents[2] / "data" / "bvh-corpus"
    cmu = load_motion(corpus / "01_01.bvh.gz").skeleton
    assert detect_roles(cmu).preset == "cmu-cgspeed"
    from motion.retarget.names import SIGNATURES

    cgspeed_only = SIGNATURES["cmu-cgspeed"]
    mixamo_names = tuple(
        n + "_x" if n in cgspeed_only else "Spine2" if n == "Spine1" else n for n in cmu.names
    )
    other = Skeleton(mixamo_names, cmu.parents, cmu.offsets, cmu.channels)
    assert detect_roles(other).preset == "mixamo"
    assert detect_roles(cmu).joints == detect_roles(other).joints  # the same roles either way


def test_a_map_may_name_toes_the_source_lacks() -> None:
    """A role map naming the character's toes (CMU-Daz sources have none) was an error; now the
    character knows them (its feet stand on them) and the result is the preset-named rig's."""
    from motion.retarget.character import gltf_character

    from .gltf_rig import unreal_character_glb
    from .namings import renamed_glb, role_map

    src = walk(120)
    preset = gltf_character(unreal_character_glb())
    own = gltf_character(renamed_glb(unreal_character_glb(), "own"))
    corr = correspond(src.skeleton, own.skeleton, role_map("own"))
    assert own.skeleton.names[corr.target_roles["LeftToes"]] == "L_digiti"
    assert "LeftToes" not in corr.source_roles and corr.target_roles["LeftToes"] not in corr.pairs
    assert not corr.warnings
    a, b = retarget(src, preset), retarget(src, own, name_map=role_map("own"))
    np.testing.assert_allclose(a.global_positions(), b.global_positions(), atol=1e-9)


def test_a_map_that_leaves_limbs_undriven_names_them() -> None:
    """A map naming only the roles the missing-joint error lists drove 7 joints and silently froze
    the upper body; the correspondence now says which limbs keep their rest pose."""
    from motion.retarget.character import gltf_character

    from .gltf_rig import unreal_character_glb
    from .namings import renamed_glb, role_map

    own = gltf_character(renamed_glb(unreal_character_glb(), "own"))
    legs = {r: j for r, j in role_map("own").items() if r in REQUIRED}
    corr = correspond(walk(2).skeleton, own.skeleton, legs)
    assert len(corr.pairs) == 7
    (warning,) = corr.warnings
    for limb in ("head", "left arm (left shoulder", "right arm", "spine and neck"):
        assert limb in warning
    assert "7 of 24 joints driven" in warning and "--map" in warning
