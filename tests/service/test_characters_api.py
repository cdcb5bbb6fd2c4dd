"""``/v1/characters``: a character's binding to a viewer's skeleton and its model."""

from __future__ import annotations

import io
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from motion import write_bvh
from motion.io import load_motion
from motion.retarget import retarget
from motion.retarget.binding import apply_binding, bind
from motion.retarget.character import gltf_character
from tests.motion.retarget.characters import character
from tests.motion.retarget.gltf_rig import unreal_character_glb

from .test_api import error_of


def _walk():  # type: ignore[no-untyped-def]
    m = load_motion("sample:walk")
    return m.scaled(m.metres_per_unit, "m")


def skeleton_json(m: Any) -> dict[str, Any]:
    sk = m.skeleton
    return {
        "names": list(sk.names),
        "parents": [int(p) for p in sk.parents],
        "offsets": sk.offsets.tolist(),
        "end_sites": [
            {"parent": int(p), "offset": o.tolist()}
            for p, o in zip(sk.end_site_parents, sk.end_site_offsets, strict=True)
        ],
    }


def example_json(m: Any) -> dict[str, Any]:
    return {"fps": m.fps, "root": m.root_positions.tolist(), "rotations": m.rotations.tolist()}


@pytest.fixture(scope="module")
def hero_file(client: TestClient) -> dict[str, Any]:
    r = client.post("/v1/files", files={"file": ("hero.glb", unreal_character_glb())})
    assert r.status_code in (200, 201), r.text
    return dict(r.json())


def test_a_glb_characters_binding_is_the_retargetings_transfer(
    client: TestClient, hero_file: dict[str, Any]
) -> None:
    """With example frames, the binding the page applies per frame gives what the download's
    retargeting gives without its foot planting."""
    walk = _walk().slice(0, 120)
    body = {"character": hero_file["id"], "skeleton": skeleton_json(walk), "example": example_json(walk)}
    r = client.post("/v1/characters/binding", json=body)
    assert r.status_code == 200, r.text
    got = r.json()
    assert got["character"] == {"kind": "file", "id": hero_file["id"], "name": "hero.glb"}
    hero = gltf_character(unreal_character_glb())
    want = bind(walk.skeleton, hero, example=walk).to_json()
    assert got["source"] == want["source"] and got["target"] == want["target"]
    assert [j["joint"] for j in got["joints"]] == [j["joint"] for j in want["joints"]]
    assert got["hips"] == pytest.approx(want["hips"])
    # the binding as served (rounded) applied to the frames: the retargeting within 0.1 mm
    b = bind(walk.skeleton, hero, example=walk)
    served = np.array([j["offset"] for j in got["joints"]])
    moved = apply_binding(
        type(b)(**{**{f: getattr(b, f) for f in b.__slots__}, "offsets": served}), walk, hero
    )
    want_pos = retarget(walk, hero, feet="free").global_positions()
    assert np.abs(moved.global_positions() - want_pos).max() < 1e-4


def test_a_bvh_clip_is_a_character_too(client: TestClient) -> None:
    buf = io.StringIO()
    write_bvh(character("mixamo", scale=1.25), buf)
    clip = client.post("/v1/clips", files={"file": ("mixamo-bind.bvh", buf.getvalue().encode())}).json()
    walk = _walk()
    r = client.post(
        "/v1/characters/binding", json={"character": "mixamo-bind.bvh", "skeleton": skeleton_json(walk)}
    )
    assert r.status_code == 200, r.text
    got = r.json()
    assert got["character"]["kind"] == "clip" and got["character"]["id"] == clip["id"]
    assert got["hips"]["joint"] == "mixamorig:Hips" and got["hips"]["scale"] == pytest.approx(1.25, rel=0.05)
    # the clip's units (cm) are not the binding's: the floors are metres
    assert 0.02 < got["hips"]["target_floor"] < 0.2


def test_the_model_is_the_uploaded_file(client: TestClient, hero_file: dict[str, Any]) -> None:
    body = {"character": hero_file["id"], "skeleton": skeleton_json(_walk())}
    r = client.post("/v1/characters/model", json=body)
    assert r.status_code == 200 and r.headers["content-type"] == "model/gltf-binary"
    assert r.content == unreal_character_glb()


def test_what_is_not_a_character_is_refused_by_name(client: TestClient, hero_file: dict[str, Any]) -> None:
    walk = _walk()
    sk = skeleton_json(walk)
    r = client.post("/v1/characters/binding", json={"character": "nobody.glb", "skeleton": sk})
    assert "no character 'nobody.glb'" in error_of(r, 404, "not_found")["message"]
    midi = client.post("/v1/files", files={"file": ("song.mid", b"MThd\0\0\0\6\0\0\0\1\1\xe0")}).json()
    r = client.post("/v1/characters/model", json={"character": midi["id"], "skeleton": sk})
    assert "song.mid is not a character" in error_of(r, 422, "not_a_character")["message"]
    broken = dict(sk, parents=sk["parents"][:-1])
    r = client.post("/v1/characters/binding", json={"character": hero_file["id"], "skeleton": broken})
    message = error_of(r, 422, "invalid_skeleton")["message"]
    assert f"{len(sk['names'])} names, {len(sk['names']) - 1} parents" in message
    arm = {"names": ["a", "b"], "parents": [-1, 0], "offsets": [[0, 0, 0], [0, 1, 0]]}
    r = client.post("/v1/characters/binding", json={"character": hero_file["id"], "skeleton": arm})
    assert "hero.glb cannot follow this skeleton" in error_of(r, 422, "retarget_failed")["message"]
    cycle = dict(arm, parents=[-1, 1])
    r = client.post("/v1/characters/binding", json={"character": hero_file["id"], "skeleton": cycle})
    assert "not a joint tree" in error_of(r, 422, "invalid_skeleton")["message"]
    # degenerate skeletons the mannequin cannot wear: 422 naming why, never a 500
    point = {"names": ["a"], "parents": [-1], "offsets": [[0, 0, 0]]}
    for route in ("binding", "model"):
        r = client.post(f"/v1/characters/{route}", json={"skeleton": point})
        assert "less than 1 cm" in error_of(r, 422, "invalid_skeleton")["message"]
    far = dict(arm, offsets=[[0, 0, 0], [0, 1e5, 0]])
    r = client.post("/v1/characters/model", json={"skeleton": far})
    error_of(r, 422, "invalid_request")
    zero = {"fps": 30, "root": [[0, 0, 0]] * 2, "rotations": [[[0, 0, 0, 0]] * len(sk["names"])] * 2}
    r = client.post(
        "/v1/characters/binding", json={"character": hero_file["id"], "skeleton": sk, "example": zero}
    )
    assert "not a quaternion" in error_of(r, 422, "invalid_skeleton")["message"]


def test_without_a_character_the_mannequin_wears_the_skeleton(client: TestClient) -> None:
    """No character: Segue's mannequin made on the skeleton itself, every joint following itself."""
    walk = _walk()
    body = {"skeleton": skeleton_json(walk)}
    r = client.post("/v1/characters/model", json=body)
    assert r.status_code == 200 and r.content[:4] == b"glTF"
    mannequin = gltf_character(r.content)
    assert mannequin.skeleton.names == walk.skeleton.names
    got = client.post("/v1/characters/binding", json=body).json()
    assert got["character"] == {"kind": "mannequin", "id": None, "name": "mannequin"}
    assert (
        [j["joint"] for j in got["joints"]]
        == [j["source"] for j in got["joints"]]
        == list(walk.skeleton.names)
    )
    assert got["hips"] == {
        "joint": "hip",
        "source": "hip",
        "scale": 1.0,
        "source_floor": 0.0,
        "target_floor": 0.0,
    }


def test_a_bvh_characters_model_is_its_skeleton_on_the_mannequin(client: TestClient) -> None:
    buf = io.StringIO()
    write_bvh(character("unreal", scale=0.9), buf)
    client.post("/v1/clips", files={"file": ("unreal-bind.bvh", buf.getvalue().encode())})
    r = client.post(
        "/v1/characters/model", json={"character": "unreal-bind.bvh", "skeleton": skeleton_json(_walk())}
    )
    assert r.status_code == 200, r.text
    assert gltf_character(r.content).skeleton.names == character("unreal", scale=0.9).skeleton.names


def test_a_result_download_wears_the_mannequin(
    client: TestClient, walk_db: dict[str, Any], hero_file: dict[str, Any]
) -> None:
    """``mesh=body``: a GLB download on Segue's mannequin (what the viewer shows a result on when
    no character is chosen), with the contacts measured on it; a glTF character wears its own."""
    from tests.glb_writer import read_glb

    from .conftest import WALK_CLIP, wait_events
    from .test_api import submit

    job = submit(
        client, {"engine": "clip", "database": walk_db["id"], "clip": WALK_CLIP, "start": 0, "end": 75}
    )
    events = wait_events(client, job["id"])
    assert events[-1]["type"] == "done", events[-1]["data"]
    url = f"/v1/jobs/{job['id']}/result"
    r = client.get(url, params={"format": "glb", "mesh": "body", "events": "contacts", "max_fps": 30})
    assert r.status_code == 200, r.text
    doc, _ = read_glb(r.content)
    assert [m["name"].rsplit("_", 1)[-1] for m in doc["meshes"]] == ["body"]
    assert doc["animations"] and any(e["type"] == "contact" for e in doc["animations"][0]["extras"]["events"])
    bones, _ = read_glb(client.get(url, params={"format": "glb"}).content)
    assert [m["name"].rsplit("_", 1)[-1] for m in bones["meshes"]] == ["bones"]
    assert (
        "format=glb"
        in error_of(client.get(url, params={"format": "bvh", "mesh": "body"}), 422, "invalid_request")[
            "message"
        ]
    )
    r = client.get(url, params={"format": "glb", "mesh": "body", "character": hero_file["id"]})
    assert "wears its own mesh" in error_of(r, 422, "invalid_request")["message"]
