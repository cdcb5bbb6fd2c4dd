"""Feet on the floor, measured on the character's own skinned mesh (issue 37's bars): a skinned
character (Segue's mannequin on the test game rig: a heel behind the ankle, a ball, toes, soles
flat on the rest floor) under Unreal names, Mixamo names and names of its own with a role map
naming its toes, retargeted as ``segue retarget`` does (its mesh's soles on the floor, contacts
by role), written into its own file, the mesh deformed as a viewer deforms it:

* the mesh never more than 1 cm under its rest floor;
* planted soles (the file's contact events) within 2.5 cm of it;
* no foot faster than 1.3 times the source's fastest foot, scaled to the character;
* the same contacts on every naming, one per plant.

Before this work the walk sank the mesh 7.9 cm (toes plunging at push-off), the dance 6.6 cm with
a foot at 2.1 times the source's speed, Mixamo names doubled the contacts, and the map could not
name the toes (15 cm under the floor on the dance).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from motion import Motion
from motion.io import load_motion
from motion.refpose import without_reference_lead

from .mesh_feet import measure, written
from .namings import BANDAI_WALK, NAMINGS, bandai_rig, game_rig, mannequin_character, role_map

SINK_CM, LIFT_CM, SPEED_RATIO = 1.0, 2.5, 1.3


def retargeted(source: Motion, naming: str) -> bytes:
    """``source`` on the mannequin named after ``naming``: its own file with the animation and
    contact events, as ``segue retarget ... --events contacts`` writes it."""
    return written(source, mannequin_character(naming), role_map("own") if naming == "own" else None)


def figures(source: Motion) -> dict[str, dict[str, Any]]:
    return {naming: measure(retargeted(source, naming), source, game_rig(), naming) for naming in NAMINGS}


def check(got: dict[str, dict[str, Any]]) -> None:
    for naming, f in got.items():
        assert f["sink_cm"] <= SINK_CM, f"{naming}: the mesh {f['sink_cm']} cm under the floor"
        assert (
            f["lift_cm"] is not None and f["lift_cm"] <= LIFT_CM
        ), f"{naming}: a planted sole {f['lift_cm']} cm up"
        assert (
            f["foot_speed_ratio"] <= SPEED_RATIO
        ), f"{naming}: a foot at {f['foot_speed_ratio']}x the source's"
        assert f["contacts_off_feet"] == 0
    assert len({f["contacts"] for f in got.values()}) == 1, {n: f["contacts"] for n, f in got.items()}


def test_the_walk_keeps_the_mesh_on_the_floor_on_every_naming() -> None:
    walk, _ = without_reference_lead(load_motion("sample:walk"))
    got = figures(walk)
    check(got)
    assert got["unreal"]["contacts"] == got["unreal"]["source_plants"] == 5  # one per plant


@pytest.mark.slow
def test_the_rhythm_demos_dance_keeps_the_mesh_on_the_floor_on_every_naming(tmp_path: Path) -> None:
    from service.demos import run_demo

    run_demo("rhythm", tmp_path, say=lambda *_: None)
    check(figures(load_motion(tmp_path / "rhythm" / "dance.bvh")))


def test_contact_events_start_and_end_where_the_soles_touch_the_floor_on_a_bandai_skeleton() -> None:
    """A Bandai-Namco skeleton (a clip's first frame as its rest pose) wearing the mannequin: the
    joints' plants end after the sole has left the floor (a toe rising slowly); the contact
    events end where the sole leaves it. Before, planted soles were up to 8.4 cm up at the end
    of the walk's events."""
    if not BANDAI_WALK.is_file():
        pytest.skip(f"no {BANDAI_WALK} (../shared/data)")
    rest = bandai_rig()
    walk, _ = without_reference_lead(load_motion("sample:walk"))
    f = measure(written(walk, mannequin_character("unreal", rest)), walk, rest, "unreal")
    assert f["lift_cm"] is not None and f["lift_cm"] <= LIFT_CM, f
    assert f["contacts"] == f["source_plants"] == 5  # one per plant, none lost
