"""Planted feet stay planted and above the floor after retargeting onto other proportions."""

from __future__ import annotations

import numpy as np

from motion.contacts import detect_contacts
from motion.retarget import correspond, retarget
from motion.retarget.legik import FOOT_ROLES, floor_heights, foot_joints, settle

from .characters import character, walk


def test_planted_feet_stay_planted_and_above_the_floor() -> None:
    src = walk(360)
    char = character("unreal", scale=0.9, shin=1.25)  # longer shins than the source's
    roles = correspond(src.skeleton, char.skeleton).target_roles
    joints = foot_joints(roles)
    raw = settle(retarget(src, char, feet="free"), roles, char)  # the body's height as planted
    out = retarget(src, char)
    raw_pos, pos = raw.global_positions(), out.global_positions()
    _, flags = detect_contacts(raw, joints, positions=raw_pos)
    planted = flags[1:] & flags[:-1]

    def slide(p: np.ndarray) -> float:
        v = np.linalg.norm(np.diff(p[:, joints][:, :, [0, 2]], axis=0), axis=-1) * out.fps
        return float(np.mean(v[planted]))

    m = out.metres_per_unit
    assert slide(pos) * m < 0.02, f"planted feet slide {slide(pos) * m:.3f} m/s"
    assert slide(pos) < 0.5 * slide(raw_pos)
    floor = floor_heights(roles, raw_pos)
    assert np.all(pos[:, joints, 1] >= floor - 1e-6 / m), "a foot goes under its floor"
    # the IK lifts and pins; it does not float the feet: the lowest foot stays as high as before,
    # or lower (planted soles are brought down onto the floor)
    lowest, lowest_raw = ((p[:, joints, 1] - floor).min(axis=1) for p in (pos, raw_pos))
    assert (np.median(lowest) - np.median(lowest_raw)) * m < 0.01
    assert [r for r in FOOT_ROLES if r in roles] == ["LeftFoot", "RightFoot"]  # CMU-Daz: no toes


def test_planted_feet_are_the_characters_own_flat_feet() -> None:
    """From a CMU source (its foot aimed along the ankle-to-toe-tip line), a game rig's planted
    foot is its rest foot: not pitched, its ankle and ball at their rest heights (sole and toe
    on the floor; the issue saw the toe never below 7.6 cm)."""
    from motion.io import load_motion
    from motion.retarget.character import gltf_character

    from .gltf_rig import unreal_character_glb

    char = gltf_character(unreal_character_glb())
    out = retarget(load_motion("sample:walk-05-01"), char)
    names = out.skeleton.names
    rest = char.global_positions()[0]
    pos = out.global_positions()
    for side in "lr":
        foot, ball = names.index(f"foot_{side}"), names.index(f"ball_{side}")
        _, flags = detect_contacts(out, np.array([foot, ball]), positions=pos)
        flat = flags.all(axis=1)
        assert flat.sum() > 20
        v, v0 = pos[flat, ball] - pos[flat, foot], rest[ball] - rest[foot]
        pitch = np.degrees(
            np.arcsin(v[:, 1] / np.linalg.norm(v, axis=1)) - np.arcsin(v0[1] / np.linalg.norm(v0))
        )
        # (a planted foot whose leg cannot bring its sole down pitches toes down onto the floor:
        # 1.6 and 3.9 degrees median here; the toes were lifted 4-14 degrees before issue 15)
        assert abs(np.median(pitch)) < 5.0
        assert abs(np.median(pos[flat, ball, 1]) - rest[ball, 1]) < 0.01  # metres
        assert abs(np.median(pos[flat, foot, 1]) - rest[foot, 1]) < 0.015  # (pitched: up to 1.1 cm)
