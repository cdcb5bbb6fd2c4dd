"""Held-out CMU motion (``../shared/data``, not a bundled sample) retargeted onto the skinned
Unreal-style test character through the command line: the output binds to the character."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from service.cli import main
from tests.glb_writer import read_glb

from .gltf_rig import NAMES, PARENTS, animated_world, node_index, unreal_character_glb

DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data"
CLIPS = ("cmu-daz/walks/08_03.bvh", "cmu-walks/007_02.bvh")


@pytest.mark.parametrize("clip", CLIPS)
def test_held_out_motion_binds_to_an_unreal_style_character(tmp_path: Path, clip: str) -> None:
    if not (DATA / clip).is_file():
        pytest.skip(f"shared motion data not found: {DATA / clip}")
    hero = tmp_path / "hero.glb"
    hero.write_bytes(unreal_character_glb())
    out = tmp_path / "out.glb"
    assert (
        main(["retarget", str(DATA / clip), "--to", str(hero), "--out", str(out), "--target", "unreal", "-q"])
        == 0
    )
    before, _ = read_glb(hero.read_bytes())
    doc, binary = read_glb(out.read_bytes())
    skin = doc["skins"][0]
    names = [doc["nodes"][j]["name"] for j in skin["joints"]]
    assert names == list(NAMES)  # exactly the character's joints ...
    parent = {c: i for i, nd in enumerate(doc["nodes"]) for c in nd.get("children", [])}
    got_parents = [
        names.index(doc["nodes"][parent[j]]["name"]) if k else -1 for k, j in enumerate(skin["joints"])
    ]
    assert tuple(got_parents) == PARENTS  # ... with the same parents
    assert doc["meshes"] == before["meshes"] and doc["materials"] == before["materials"]
    assert doc["nodes"] == before["nodes"]  # no joint added, none renamed or moved
    animated = {c["target"]["node"] for c in doc["animations"][0]["channels"]}
    assert animated <= set(skin["joints"])  # nothing above root
    world = animated_world(doc, binary)
    root, pelvis = world[node_index(doc, "root")], world[node_index(doc, "pelvis")]
    assert np.abs(root[:, 1, 3]).max() < 1e-6
    assert np.abs(root[:, [0, 2], 3] - pelvis[:, [0, 2], 3]).max() < 1e-5
    assert np.linalg.norm(root[-1, [0, 2], 3] - root[0, [0, 2], 3]) > 1.0
