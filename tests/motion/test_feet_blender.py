"""The retargeted character's mesh as Blender deforms it (Blender 5 as a module, tests/blender.py):
Segue's numpy linear blend skinning (:mod:`motion.skinning`, what ``bench/feet_mesh.py`` measures
the feet with) gives Blender's own vertices, and the file plays Segue's animation first even when
the character already had one.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from motion import Motion
from motion.export.bind import bound_glb
from motion.io import load_motion
from motion.refpose import without_reference_lead
from motion.retarget import retarget
from motion.retarget.character import gltf_character
from motion.skinning import animation_pose, read_skinned_mesh, skin

from ..blender import run_blender
from .retarget.namings import mannequin_character

pytestmark = pytest.mark.slow

TOOLS = Path(__file__).resolve().parents[1] / "tools"
FRAMES = (0, 40, 80, 120, 160)


@pytest.fixture(scope="module")
def blender(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    folder = tmp_path_factory.mktemp("feet-blender")
    hero = mannequin_character("mixamo")
    mesh = read_skinned_mesh(hero)
    walk, _ = without_reference_lead(load_motion("sample:walk"))
    idle = replace(retarget(walk.slice(0, 20), gltf_character(hero), mesh=mesh), name="idle")
    with_idle = bound_glb(hero, idle)  # a character that already has an animation
    moved = retarget(walk.slice(0, 200), gltf_character(hero), mesh=mesh)
    data = bound_glb(with_idle, moved)
    path = folder / "walk.glb"
    path.write_bytes(data)
    times = ",".join(f"{f / moved.fps:.6f}" for f in FRAMES)
    out = folder / "skin.json"
    res = run_blender(TOOLS / "blender_skin.py", str(path), str(out), times)
    if not out.is_file():
        raise AssertionError(
            f"Blender did not import {path.name}:\n{res.stdout[-3000:]}\n{res.stderr[-2000:]}"
        )
    return {"report": json.loads(out.read_text()), "data": data, "moved": moved}


def test_numpy_skinning_is_blenders_deformation(blender: dict[str, object]) -> None:
    report, data = blender["report"], blender["data"]
    assert isinstance(report, dict) and isinstance(data, bytes)
    (got,) = report["meshes"]
    mesh = read_skinned_mesh(data)
    assert mesh is not None
    names, pos, rots, _ = animation_pose(data, 0)
    ours = skin(mesh.reindexed(names), pos[list(FRAMES)], rots[list(FRAMES)])
    for k in range(len(FRAMES)):
        theirs = np.array(got["frames"][k])
        # Blender's importer may split or reorder vertices: compare the two point sets both ways
        far = max(cKDTree(theirs).query(ours[k])[0].max(), cKDTree(ours[k]).query(theirs)[0].max())
        assert far < 1e-3, f"frame {FRAMES[k]}: a vertex {far * 1000:.2f} mm from Blender's"
        assert abs(theirs[:, 1].min() - ours[k][:, 1].min()) < 1e-4  # the lowest vertex (the sole)


def test_blender_plays_segues_animation_on_a_character_that_had_one(blender: dict[str, object]) -> None:
    report, moved = blender["report"], blender["moved"]
    assert isinstance(report, dict) and isinstance(moved, Motion)
    (active,) = report["active"]  # Blender makes the file's first animation the active action
    assert active is not None and active.startswith(moved.name), active  # not "idle"
