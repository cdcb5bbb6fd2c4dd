"""``POST /v1/clips`` with files nobody here wrote: a real BVH that needs a warning, a glTF file's
animation, and the checks a database spec and a job meet at submission (issue 39)."""

from __future__ import annotations

import gzip
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient

from motion.bvh import parse_bvh
from motion.export.glb import glb_bytes
from motion.io import load_motion
from motion.samples import sample_path

from .conftest import WALK_CLIP, ready_database, wait_events

CORPUS = Path(__file__).resolve().parents[1] / "data" / "bvh-corpus"


def upload(client: TestClient, name: str, data: bytes) -> dict[str, Any]:
    r = client.post("/v1/clips", files={"file": (name, data)})
    assert r.status_code in (200, 201), r.text
    return dict(r.json())


def test_a_real_bvh_with_an_off_frame_count_is_read_with_its_warning(client: TestClient) -> None:
    # Regression (issue 39): assimp's Boxing_Toes.bvh declares 3069 frames and holds 3070: a 400.
    clip = upload(client, "Boxing_Toes.bvh.gz", (CORPUS / "Boxing_Toes.bvh.gz").read_bytes())
    assert clip["frames"] == 3070 and clip["format"] == "bvh"
    assert clip["warnings"] == [
        "line 128: Frames: 3069, but the file holds 3070 frame lines: read 3070 (the lines present win)"
    ]
    # the page draws what the service read: the same frames, as BVH a browser's reader takes
    read = client.get(f"/v1/clips/{clip['id']}/bvh", params={"read": "true"})
    assert read.status_code == 200
    assert parse_bvh(read.content).num_frames == 3070
    assert client.get(f"/v1/clips/{clip['id']}").json()["warnings"] == clip["warnings"]


def test_a_header_over_the_joint_frame_limit_is_refused_at_once(client: TestClient) -> None:
    # Issue 40.3: a small gzip declaring 1,900,000 frames (21 joints: 39.9 M joint-frames, over the
    # default 10 M) is refused from its header, before any row is read or a worker is asked.
    text = gzip.decompress((CORPUS / "Boxing_Toes.bvh.gz").read_bytes())
    head, _, rows = text.partition(b"MOTION")
    row = rows.split(b"\n")[3] + b"\n"
    body = head + b"MOTION\nFrames: 1900000\nFrame Time: 0.01\n" + row * 20_000
    r = client.post("/v1/clips", files={"file": ("bomb.bvh.gz", gzip.compress(body))})
    assert r.status_code == 400, r.text
    message = r.json()["error"]["message"]
    assert "bomb.bvh.gz:128" in message and "joint-frame limit" in message


def _walk_glb() -> bytes:
    return glb_bytes(load_motion("sample:walk").to_units("m"))


def test_a_glb_is_a_clip_of_the_same_frames_and_height(client: TestClient, walk_clip: dict[str, Any]) -> None:
    clip = upload(client, "walk.glb", _walk_glb())
    assert clip["format"] == "gltf" and clip["units"] == "m"
    assert clip["animations"] == [{"name": "07_01_walk_daz", "frames": 317, "fps": 120.0}]
    assert (clip["frames"], clip["fps"], clip["joints"]) == (
        walk_clip["frames"],
        walk_clip["fps"],
        walk_clip["joints"],
    )
    assert abs(clip["height_m"] - walk_clip["height_m"]) < 1e-3  # one height for a BVH and its GLB
    read = client.get(f"/v1/clips/{clip['id']}/bvh", params={"read": "true"})
    assert parse_bvh(read.content).num_frames == 317
    assert client.get(f"/v1/clips/{clip['id']}/bvh").content[:4] == b"glTF"  # as uploaded
    db = ready_database(
        client, {"kind": "clips", "clips": [{"clip": clip["id"], "name": "walk-glb"}], "fps": 30}
    )
    assert db["summary"]["clips"][0]["frames"] == 80  # 317 frames at 120 fps, at 30 fps


def test_a_broken_gltf_upload_is_named_as_gltf(client: TestClient) -> None:
    # Regression: a glTF upload that cannot be read answered 400 ``invalid_bvh``
    good = _walk_glb()
    for name, data, says in [
        ("cut.glb", good[: len(good) // 2], "cut.glb"),
        (
            "still.glb",
            glb_bytes(load_motion("sample:walk").slice(0, 1).to_units("m"), animation=False),
            "animation",
        ),
    ]:
        r = client.post("/v1/clips", files={"file": (name, data)})
        assert r.status_code == 400, r.text
        err = r.json()["error"]
        assert err["code"] == "invalid_gltf" and says in err["message"], err
    bvh = client.post("/v1/clips", files={"file": ("x.bvh", b"HIERARCHY\nROOT")})
    assert bvh.json()["error"]["code"] == "invalid_bvh"


def test_a_spec_is_checked_against_its_clips_at_submission(
    client: TestClient, walk_clip: dict[str, Any]
) -> None:
    glb = upload(client, "walk.glb", _walk_glb())
    boxing = upload(client, "Boxing_Toes.bvh.gz", (CORPUS / "Boxing_Toes.bvh.gz").read_bytes())
    cases = [
        ([{"clip": glb["id"], "animation": "run"}], "no animation 'run'; the file has 0: '07_01_walk_daz'"),
        ([{"clip": walk_clip["id"], "animation": 0}], "'animation' is for glTF clips"),
        # Regression (issue 39): clips of two skeletons were accepted and the build failed later
        ([{"clip": walk_clip["id"]}, {"clip": boxing["id"]}], "segue retarget"),
    ]
    for clips, says in cases:
        r = client.post("/v1/databases", json={"kind": "clips", "clips": clips})
        assert r.status_code == 422, r.text
        assert says in r.json()["error"]["message"]


def test_a_control_pair_of_unequal_lengths_is_refused_or_trimmed(
    client: TestClient, walk_clip: dict[str, Any]
) -> None:
    # Regression (issue 39): a pair of 688 and 1128 frames was cut to the shorter without a word.
    short = sample_path("walk-05-01")  # the same CMU-Daz skeleton, 150 frames at 30 fps
    other = upload(client, short.name, short.read_bytes())
    pair = {"control": WALK_CLIP, "target": other["name"].removesuffix(".bvh.gz")}
    spec: dict[str, Any] = {
        "kind": "control",
        "clips": [
            {"clip": walk_clip["id"], "name": WALK_CLIP},
            {"clip": other["id"], "name": pair["target"]},
        ],
        "pairs": [pair],
        "segmentation": {"method": "fixed", "seconds": 1.0},
    }
    r = client.post("/v1/databases", json=spec)
    assert r.status_code == 422, r.text
    message = r.json()["error"]["message"]
    assert f"control '{WALK_CLIP}' has 80 frames and target '{pair['target']}' 150 at 30 fps" in message
    assert '"unequal_pairs": "trim"' in message
    r = client.post("/v1/databases", json={**spec, "unequal_pairs": "trim"})
    assert r.status_code == 202, r.text
    events = wait_events(client, r.json()["build_job"])
    assert events[-1]["type"] == "done", events[-1]
    said = [e["data"].get("message", "") for e in events if e["type"] == "progress"]
    assert any("both cut to 80 frames (unequal_pairs: trim)" in m for m in said), said


def test_a_job_naming_frames_past_a_clip_is_refused_at_submission(
    client: TestClient, walk_db: dict[str, Any]
) -> None:
    request = {"engine": "clip", "database": walk_db["id"], "clip": WALK_CLIP, "start": 0, "end": 5000}
    r = client.post("/v1/jobs", json=request)
    assert r.status_code == 422 and r.json()["error"]["code"] == "unknown_clip", r.text
    assert "end: frame 4999 is past the end of clip" in r.json()["error"]["message"]
    r = client.post("/v1/jobs", json={**request, "clip": "nope", "end": 5})
    assert r.status_code == 422 and "no clip named 'nope'" in r.json()["error"]["message"]
