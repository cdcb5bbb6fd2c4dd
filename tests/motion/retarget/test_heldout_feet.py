"""Issue 37's done-bar on a held-out character, not Segue's mannequin (:mod:`.heldout`: built by
Blender, 54 bones, its own proportions, a mesh skinned by Blender's automatic weights), under
Unreal names, Mixamo names and its own names with a role map naming its toes, on ``sample:walk``
and the rhythm demo's dance, retargeted as ``segue retarget --to CHAR.glb --events contacts``
writes it and measured on its own skin as a viewer plays the file (:mod:`motion.skinning`; the
first test checks that against Blender's own deformation of the same file):

* the mesh never more than 1 cm under its rest floor;
* planted soles (the file's contact events) within 2.5 cm of it;
* no foot faster than 1.3 times the source's fastest foot, scaled to the character;
* the same contacts on every naming.

Needs Blender as a module (``SEGUE_BPY_PYTHON``, tests/blender.py); skipped with a message
without it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree

from motion import Motion
from motion.io import load_motion
from motion.refpose import without_reference_lead
from motion.retarget.character import gltf_character
from motion.skinning import animation_pose, read_skinned_mesh, skin

from ...blender import bpy_python, run_blender
from .heldout import NAMINGS, build_heldout, heldout_glb, heldout_role_map, name_of
from .mesh_feet import measure, written

pytestmark = pytest.mark.slow

SINK_CM, LIFT_CM, SPEED_RATIO = 1.0, 2.5, 1.3
TOOLS = Path(__file__).resolve().parents[2] / "tools"


@pytest.fixture(scope="module")
def character(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """The held-out character in its own names (Blender builds it)."""
    return build_heldout(bpy_python(), tmp_path_factory.mktemp("heldout"))


def retargeted(source: Motion, own: bytes, naming: str) -> bytes:
    """``source`` on the character named after ``naming``, in its own file with contact events,
    as ``segue retarget SOURCE --to CHAR.glb --out OUT.glb --events contacts [--map]`` does."""
    return written(source, heldout_glb(own, naming), heldout_role_map() if naming == "own" else None)


def figures(source: Motion, own: bytes) -> dict[str, dict[str, Any]]:
    rest = gltf_character(heldout_glb(own, "unreal"))
    return {n: measure(retargeted(source, own, n), source, rest, n, name_of) for n in NAMINGS}


def check(got: dict[str, dict[str, Any]]) -> None:
    for naming, f in got.items():
        assert f["sink_cm"] <= SINK_CM, f"{naming}: the mesh {f['sink_cm']} cm under its floor ({f})"
        assert f["lift_cm"] is not None and f["lift_cm"] <= LIFT_CM, f"{naming}: a planted sole up ({f})"
        assert f["foot_speed_ratio"] <= SPEED_RATIO, f"{naming}: a foot too fast ({f})"
        assert f["contacts"] > 0 and f["contacts_off_feet"] == 0
    assert len({f["contacts"] for f in got.values()}) == 1, {n: f["contacts"] for n, f in got.items()}


def test_numpy_skinning_is_blenders_on_the_heldout_character(character: bytes, tmp_path: Path) -> None:
    walk, _ = without_reference_lead(load_motion("sample:walk"))
    data = retargeted(walk.slice(0, 120), character, "mixamo")
    path = tmp_path / "walk.glb"
    path.write_bytes(data)
    frames = (0, 50, 100)
    names, pos, rots, times = animation_pose(data, 0)
    out = tmp_path / "skin.json"
    res = run_blender(
        TOOLS / "blender_skin.py", str(path), str(out), ",".join(f"{times[f]:.6f}" for f in frames)
    )
    assert out.is_file(), f"Blender did not import {path.name}:\n{res.stdout[-3000:]}\n{res.stderr[-2000:]}"
    (got,) = json.loads(out.read_text())["meshes"]
    mesh = read_skinned_mesh(data)
    assert mesh is not None and mesh.num_vertices > 5000
    ours = skin(mesh.reindexed(names), pos[list(frames)], rots[list(frames)])
    for k, f in enumerate(frames):
        theirs = np.array(got["frames"][k])
        far = max(cKDTree(theirs).query(ours[k])[0].max(), cKDTree(ours[k]).query(theirs)[0].max())
        assert far < 1e-3, f"frame {f}: a vertex {far * 1000:.2f} mm from Blender's"


def test_the_walk_on_the_heldout_character(character: bytes) -> None:
    walk, _ = without_reference_lead(load_motion("sample:walk"))
    got = figures(walk, character)
    check(got)
    assert got["own"]["contacts"] == got["own"]["source_plants"] == 5  # one per plant


def test_the_rhythm_demos_dance_on_the_heldout_character(character: bytes, tmp_path: Path) -> None:
    from service.demos import run_demo

    run_demo("rhythm", tmp_path, say=lambda *_: None)
    check(figures(load_motion(tmp_path / "rhythm" / "dance.bvh"), character))
