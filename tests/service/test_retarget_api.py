"""``GET /v1/jobs/{id}/result?character=``: a result retargeted onto an uploaded character."""

from __future__ import annotations

import io
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from motion import parse_bvh, write_bvh
from motion.export.glb import glb_bytes
from tests.motion.retarget.characters import character

from .conftest import WALK_CLIP, wait_events
from .test_api import error_of, submit


def _bvh_bytes(convention: str, **kw: Any) -> bytes:
    buf = io.StringIO()
    write_bvh(character(convention, **kw), buf)
    return buf.getvalue().encode()


@pytest.fixture(scope="module")
def walk_job(client: TestClient, walk_db: dict[str, Any]) -> str:
    job = submit(
        client, {"engine": "clip", "database": walk_db["id"], "clip": WALK_CLIP, "start": 0, "end": 60}
    )
    assert wait_events(client, job["id"])[-1]["type"] == "done"
    return str(job["id"])


def test_result_on_an_uploaded_bvh_character(client: TestClient, walk_job: str) -> None:
    data = _bvh_bytes("mixamo", scale=1.2)
    clip = client.post("/v1/clips", files={"file": ("mixamo-char.bvh", data)}).json()
    r = client.get(f"/v1/jobs/{walk_job}/result", params={"format": "bvh", "character": clip["id"]})
    assert r.status_code == 200, r.text
    out, char = parse_bvh(r.content), parse_bvh(data)
    assert out.skeleton.names == char.skeleton.names and out.num_frames == 60
    # the character's offsets and units exactly (not the export target's metres)
    np.testing.assert_allclose(out.skeleton.offsets, char.skeleton.offsets, atol=1e-4)
    by_name = client.get(
        f"/v1/jobs/{walk_job}/result", params={"character": "mixamo-char.bvh", "rest": "zero"}
    )
    assert by_name.status_code == 200
    glb = client.get(f"/v1/jobs/{walk_job}/result", params={"format": "glb", "character": clip["id"]})
    assert glb.status_code == 200 and glb.content[:4] == b"glTF"


def test_result_on_an_uploaded_glb_character(client: TestClient, walk_job: str) -> None:
    data = glb_bytes(character("unreal"), ground_root=False, mesh=False)
    f = client.post("/v1/files", files={"file": ("mannequin.glb", data)}).json()
    r = client.get(f"/v1/jobs/{walk_job}/result", params={"format": "bvh", "character": f["id"]})
    assert r.status_code == 200, r.text
    assert "pelvis" in parse_bvh(r.content).skeleton.names


def test_a_glb_download_is_the_characters_own_file(client: TestClient, walk_job: str) -> None:
    from tests.glb_writer import read_glb
    from tests.motion.retarget.gltf_rig import unreal_character_glb

    hero = unreal_character_glb()
    f = client.post("/v1/files", files={"file": ("hero.glb", hero)}).json()
    for params, carrier in (
        ({"target": "unreal"}, {"root", "pelvis"}),
        ({"root_motion": "hips"}, {"pelvis"}),
    ):
        r = client.get(
            f"/v1/jobs/{walk_job}/result", params={"format": "glb", "character": f["id"], **params}
        )
        assert r.status_code == 200, r.text
        doc, _ = read_glb(r.content)
        before, _ = read_glb(hero)
        assert doc["nodes"] == before["nodes"] and doc["meshes"] == before["meshes"]
        moved = {
            doc["nodes"][c["target"]["node"]]["name"]
            for c in doc["animations"][0]["channels"]
            if c["target"]["path"] == "translation"
        }
        assert moved == carrier


def test_character_errors(client: TestClient, walk_job: str) -> None:
    err = error_of(client.get(f"/v1/jobs/{walk_job}/result", params={"character": "nope"}), 404, "not_found")
    assert "no character 'nope'" in err["message"]
    text = _bvh_bytes("unreal").replace(b"JOINT foot_l\n", b"JOINT ankle_x\n")
    clip = client.post("/v1/clips", files={"file": ("footless.bvh", text)}).json()
    err = error_of(
        client.get(f"/v1/jobs/{walk_job}/result", params={"character": clip["id"]}), 422, "retarget_failed"
    )
    assert "left foot" in err["message"]
    junk = client.post("/v1/files", files={"file": ("junk.glb", b"glTF\x02\x00")}).json()
    error_of(client.get(f"/v1/jobs/{walk_job}/result", params={"character": junk["id"]}), 400)


def test_result_on_an_uploaded_glb_clip_character(client: TestClient, walk_job: str) -> None:
    # a GLB uploaded as a clip (issue 39: a glTF file is an input everywhere a BVH is) is a
    # character too: its skin's bind pose, and a GLB download is that file with the motion added
    from motion.io import load_motion

    data = glb_bytes(load_motion("sample:walk-05-01").to_units("m"))
    clip = client.post("/v1/clips", files={"file": ("walker.glb", data)}).json()
    assert clip["format"] == "gltf"
    r = client.get(f"/v1/jobs/{walk_job}/result", params={"format": "bvh", "character": clip["id"]})
    assert r.status_code == 200, r.text
    assert parse_bvh(r.content).skeleton.names[1] == "hip"  # under the character's own ground root


def test_feet_of_a_download(client: TestClient, walk_job: str) -> None:
    """``feet=lock|grounding|free``: lock (the default on a character) holds planted feet in place
    on the floor, grounding keeps them on it along their own path, free leaves the transfer; a
    download without a character is as computed unless it asks."""
    data = _bvh_bytes("unreal", scale=0.9, shin=1.25)
    clip = client.post("/v1/clips", files={"file": ("feet-char.bvh", data)}).json()

    def get(**params: Any) -> bytes:
        r = client.get(f"/v1/jobs/{walk_job}/result", params={"format": "bvh", **params})
        assert r.status_code == 200, r.text
        return bytes(r.content)

    on_char = {feet: get(character=clip["id"], feet=feet) for feet in ("lock", "grounding", "free")}
    assert get(character=clip["id"]) == on_char["lock"]
    assert len(set(on_char.values())) == 3
    plain = get()
    assert get(feet="free") == plain and get(feet="grounding") != plain
    bad = client.get(f"/v1/jobs/{walk_job}/result", params={"feet": "stomp"})
    assert bad.status_code == 422
