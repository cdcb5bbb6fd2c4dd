"""Result downloads for clients that bind results to their own rigs (the Blender add-on):
``dancer=k`` takes one dancer out of a result of several, ``animation_only=true`` gives a glTF
character's skeleton and the animation without its mesh, and a database's summary gives the
performers' hip height (what a root path is scaled by onto a character)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from motion import parse_bvh
from tests.glb_writer import read_glb
from tests.motion.retarget.gltf_rig import unreal_character_glb

from .conftest import wait_events
from .test_api import error_of
from .test_http_edges import _ready

WALKS = ("walk-05-01", "walk-10-04", "walk-12-02", "walk")


@pytest.fixture(scope="module")
def walks_db(client: TestClient) -> dict[str, Any]:
    return _ready(client, {"kind": "graph", "clips": [{"bvh": f"sample:{c}", "name": c} for c in WALKS]})


@pytest.fixture(scope="module")
def pair_job(client: TestClient, walks_db: dict[str, Any]) -> str:
    request = {
        "engine": "graph", "database": walks_db["id"], "frames": 60, "seed": 1, "rounds": 3,
        "coupling_rounds": 1, "budget_s": 60,
        "characters": [
            {"constraints": [{"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 90}]},
            {"constraints": [{"type": "body", "frame": 0, "position": [4.0, 0.8], "heading_deg": -90}]},
        ],
    }  # fmt: skip
    r = client.post("/v1/jobs", json=request)
    assert r.status_code in (200, 201, 202), r.text
    assert wait_events(client, r.json()["id"])[-1]["type"] == "done"
    return str(r.json()["id"])


def test_one_dancer_of_several_downloads_on_its_own_skeleton(client: TestClient, pair_job: str) -> None:
    both = parse_bvh(client.get(f"/v1/jobs/{pair_job}/result", params={"format": "bvh"}).content)
    assert both.skeleton.names[0] == "world"
    for k, start in ((0, (0.0, 0.0)), (1, (4.0, 0.8))):
        r = client.get(f"/v1/jobs/{pair_job}/result", params={"format": "bvh", "dancer": k})
        assert r.status_code == 200, r.text
        one = parse_bvh(r.content)
        assert one.skeleton.names[0] == "hip" and not any(
            n.startswith("c") and "_" in n[:3] for n in one.skeleton.names
        )
        assert one.num_frames == both.num_frames
        hips = one.global_positions()[0, 0] * one.metres_per_unit
        np.testing.assert_allclose(hips[[0, 2]], start, atol=0.05)
        # the same joints, where the combined result has them
        pos = both.global_positions()[:, [both.skeleton.names.index(f"c{k}_{n}") for n in one.skeleton.names]]
        np.testing.assert_allclose(one.global_positions(), pos, atol=1e-3)
    err = error_of(client.get(f"/v1/jobs/{pair_job}/result", params={"dancer": 2}), 422, "export_failed")
    assert "has 2 dancers (0..1), not dancer 2" in err["message"]


def test_animation_only_is_the_characters_skeleton_and_the_animation(
    client: TestClient, pair_job: str
) -> None:
    hero = unreal_character_glb()
    f = client.post("/v1/files", files={"file": ("hero.glb", hero)}).json()
    params = {"format": "glb", "character": f["id"], "dancer": 1, "animation_only": "true", "fps": 24}
    r = client.get(f"/v1/jobs/{pair_job}/result", params=params)
    assert r.status_code == 200, r.text
    doc, _ = read_glb(r.content)
    before, _ = read_glb(hero)
    assert "meshes" not in doc and "meshes" in before
    skin = [before["nodes"][j]["name"] for j in before["skins"][0]["joints"]]
    assert [doc["nodes"][j]["name"] for j in doc["skins"][0]["joints"]] == skin
    (anim,) = doc["animations"]
    assert {doc["nodes"][c["target"]["node"]]["name"] for c in anim["channels"]} <= set(skin)
    times = doc["accessors"][anim["samplers"][0]["input"]]
    assert times["count"] == 48  # 60 frames at 30 fps resampled to 24
    whole = client.get(f"/v1/jobs/{pair_job}/result", params={**params, "animation_only": "false"})
    assert read_glb(whole.content)[0]["meshes"] == before["meshes"]
    err = error_of(
        client.get(f"/v1/jobs/{pair_job}/result", params={"format": "glb", "animation_only": "true"}),
        422,
        "export_failed",
    )
    assert "animation_only is for format=glb onto a glTF/GLB character" in err["message"]
    # Regression: several dancers onto one character said the motion "has no joint for: hips"
    err = error_of(
        client.get(f"/v1/jobs/{pair_job}/result", params={"format": "glb", "character": f["id"]}),
        422,
        "export_failed",
    )
    assert "has 2 dancers; a character wears one: download each with dancer=0..1" in err["message"]


def test_a_summary_gives_the_performers_hip_height(client: TestClient, walks_db: dict[str, Any]) -> None:
    skeleton = client.get(f"/v1/databases/{walks_db['id']}").json()["summary"]["skeleton"]
    assert skeleton["hip_height_m"] == pytest.approx(
        0.79, abs=0.02
    )  # the CMU walkers' hips above their ankles
