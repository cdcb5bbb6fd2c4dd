"""The HTTP/WebSocket API through TestClient: clips, databases, jobs, results, events, auth, errors."""

from __future__ import annotations

import gzip
import io
import json
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from starlette.testclient import WebSocketDenialResponse
from starlette.websockets import WebSocketDisconnect

from motion import parse_bvh
from motion.samples import sample_path
from schemas import DatabaseInfo, DatabaseStatus, ErrorResponse, JobInfo, JobStatus
from schemas.jobs import JobKind
from service.deps import app_store
from service.settings import Settings
from workers.store import Store, now

from .conftest import WALK, WALK_CLIP, wait_events

JSON = {"Content-Type": "application/json"}
"""What bodyless writes (cancel, delete) declare."""

BAD_BVH = (
    "HIERARCHY\nROOT a\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xrotation Yrotation Zrotation\n}\n"
    "MOTION\nFrames: 2\nFrame Time: 0.1\n1 2 3\n1 x 3\n"
)


def error_of(response: Any, status: int, code: str | None = None) -> dict[str, Any]:
    """The error body of a response, checked against the contract."""
    assert response.status_code == status, (response.status_code, response.text)
    body = ErrorResponse.model_validate(response.json()).error
    assert body.message
    if code is not None:
        assert body.code == code, body
    return body.model_dump()


def submit(client: TestClient, request: dict[str, Any], status: int = 202) -> dict[str, Any]:
    r = client.post("/v1/jobs", json=request)
    assert r.status_code == status, r.text
    return dict(r.json())


# -- clips --------------------------------------------------------------------------------------
def test_upload_list_get_delete(client: TestClient) -> None:
    path = sample_path("start-walk-stop")
    r = client.post("/v1/clips", files={"file": (path.name, path.read_bytes())})
    assert r.status_code == 201, r.text
    clip = r.json()
    assert clip["name"] == path.name and clip["frames"] > 100 and clip["fps"] == 120.0
    # the same bytes as a raw body: stored once
    again = client.post("/v1/clips", params={"name": "other.bvh.gz"}, content=path.read_bytes())
    assert again.status_code == 200 and again.json()["id"] == clip["id"]
    assert clip["id"] in [c["id"] for c in client.get("/v1/clips").json()]
    assert client.get(f"/v1/clips/{clip['id']}").json() == clip
    assert client.get(f"/v1/clips/{path.name}").json()["id"] == clip["id"]  # by file name
    assert client.delete(f"/v1/clips/{clip['id']}", headers=JSON).status_code == 204
    error_of(client.get(f"/v1/clips/{clip['id']}"), 404, "not_found")
    error_of(client.delete(f"/v1/clips/{clip['id']}", headers=JSON), 404, "not_found")


def test_plain_bvh_raw_upload(client: TestClient) -> None:
    lines = gzip.decompress(WALK.read_bytes()).split(b"\n")
    motion = lines.index(b"MOTION")
    five = [*lines[: motion + 1], b"Frames: 5", lines[motion + 2], *lines[motion + 3 : motion + 8], b""]
    r = client.post("/v1/clips", params={"name": "dir/../five.bvh"}, content=b"\n".join(five))
    assert r.status_code == 201, r.text
    assert r.json()["name"] == "five.bvh" and r.json()["frames"] == 5


def test_malformed_bvh_is_400_naming_file_and_line(client: TestClient) -> None:
    r = client.post("/v1/clips", files={"file": ("bad.bvh", BAD_BVH.encode())})
    err = error_of(r, 400, "invalid_bvh")
    assert "bad.bvh:11" in err["message"] and "'x'" in err["message"]
    assert not any(c["name"] == "bad.bvh" for c in client.get("/v1/clips").json())


@pytest.mark.parametrize(
    ("kwargs", "code", "status"),
    [
        ({"content": b"not a bvh"}, "invalid_request", 422),  # raw body without ?name=
        ({"files": {"other": ("a.bvh", b"x")}}, "invalid_request", 422),  # no 'file' field
        ({"content": b"", "params": {"name": "empty.bvh"}}, "empty_upload", 422),
        ({"content": b"\x1f\x8b\x08garbage", "params": {"name": "z.bvh.gz"}}, "invalid_bvh", 400),
    ],
)
def test_bad_uploads_are_4xx(client: TestClient, kwargs: dict[str, Any], code: str, status: int) -> None:
    error_of(client.post("/v1/clips", **kwargs), status, code)


def test_upload_limits(client: TestClient, override_settings: Callable[..., Settings]) -> None:
    override_settings(max_upload_bytes=10_000)
    # bytes no other test uploads (an upload of known bytes answers 200 before any check)
    data = gzip.compress(gzip.decompress(sample_path("salsa-leader").read_bytes()), mtime=12345)
    err = error_of(client.post("/v1/clips", files={"file": ("s.bvh.gz", data)}), 413, "too_large")
    assert "10000-byte limit" in err["message"]
    error_of(client.post("/v1/clips", params={"name": "s.bvh.gz"}, content=data), 413, "too_large")

    def chunks() -> Any:  # no Content-Length: the limit holds while reading
        for i in range(0, len(data), 4096):
            yield data[i : i + 4096]

    error_of(client.post("/v1/clips", params={"name": "s.bvh.gz"}, content=chunks()), 413, "too_large")
    override_settings(max_frames=1000)
    err = error_of(client.post("/v1/clips", files={"file": ("s.bvh.gz", data)}), 400, "invalid_bvh")
    assert "1000-frame limit" in err["message"] and "s.bvh.gz:" in err["message"]
    override_settings(max_joints=10)
    err = error_of(client.post("/v1/clips", files={"file": ("s.bvh.gz", data)}), 400, "invalid_bvh")
    assert "10-joint limit" in err["message"]


# -- databases ----------------------------------------------------------------------------------
def test_database_is_content_addressed(
    client: TestClient, walk_clip: dict[str, Any], walk_db: dict[str, Any]
) -> None:
    assert walk_db["clips"] == [WALK_CLIP] and walk_db["fps"] == 30.0 and walk_db["frames"] == 80
    spec = {"kind": "clips", "clips": [{"bvh": walk_clip["name"]}], "fps": 30}
    again = client.post("/v1/databases", json=spec)
    assert again.status_code == 200 and again.json() == walk_db  # no second build
    by_id = client.post(
        "/v1/databases", json={"kind": "clips", "clips": [{"clip": walk_clip["id"]}], "fps": 30}
    )
    assert by_id.status_code == 200 and by_id.json()["id"] == walk_db["id"]
    assert walk_db["id"] in [d["id"] for d in client.get("/v1/databases").json()]


def test_first_post_is_202_and_build_can_be_followed(client: TestClient, walk_clip: dict[str, Any]) -> None:
    spec = {"kind": "clips", "clips": [{"bvh": walk_clip["name"], "name": "w"}], "fps": 24}
    r = client.post("/v1/databases", json=spec)
    assert r.status_code == 202, r.text
    db = r.json()
    assert db["status"] in ("queued", "building") and db["build_job"] and db["clips"] == ["w"]
    events = wait_events(client, db["build_job"])
    assert [e["type"] for e in events][:2] == ["queued", "started"] and events[-1]["type"] == "done"
    assert client.get(f"/v1/databases/{db['id']}").json()["status"] == "ready"
    assert client.post("/v1/databases", json=spec).status_code == 200
    assert client.delete(f"/v1/databases/{db['id']}", headers=JSON).status_code == 204
    error_of(client.get(f"/v1/databases/{db['id']}"), 404, "not_found")


@pytest.mark.parametrize(
    ("spec", "status", "code", "needle"),
    [
        ({"kind": "control", "clips": [{"bvh": "07_01_walk_daz.bvh.gz"}]}, 422, "invalid_request", "pairs"),
        ({"kind": "nope", "clips": [{"bvh": "a.bvh"}]}, 422, "invalid_request", "kind"),
        ({"kind": "clips", "clips": []}, 422, "invalid_request", "clips"),
        ({"kind": "clips", "clips": [{"bvh": "a.bvh", "clip": "b"}]}, 422, "invalid_request", "exactly one"),
        ({"kind": "clips", "clips": [{"bvh": "a.bvh"}], "typo": 1}, 422, "invalid_request", "typo"),
        ({"kind": "clips", "clips": [{"bvh": "missing.bvh"}]}, 404, "not_found", "missing.bvh"),
        (
            {"kind": "clips", "clips": [{"bvh": "07_01_walk_daz.bvh.gz"}, {"bvh": "07_01_walk_daz.bvh.gz"}]},
            422,
            "invalid_request",
            "unique",
        ),
    ],
)
def test_bad_database_specs(
    client: TestClient, walk_clip: dict[str, Any], spec: dict[str, Any], status: int, code: str, needle: str
) -> None:
    err = error_of(client.post("/v1/databases", json=spec), status, code)
    assert needle in err["message"], err


def test_not_json_body_is_422(client: TestClient) -> None:
    r = client.post("/v1/databases", content=b"{oops", headers={"content-type": "application/json"})
    error_of(r, 422, "invalid_request")


def _fake_database(store: Store, status: DatabaseStatus, build_job: str | None = None) -> str:
    db_id = "feed" * 16
    info = DatabaseInfo(
        id=db_id, kind="clips", status=status, clips=["x"], build_job=build_job, created_at=now()
    )
    store.put_database_info(info, {"kind": "clips", "clips": [{"clip": "0" * 64}]})
    return db_id


def test_job_before_ready_is_409_and_building_database_cannot_be_deleted(
    client: TestClient, app: FastAPI
) -> None:
    store: Store = app.state.store
    job = JobInfo(id="b" * 32, kind=JobKind.build, status=JobStatus.running, created_at=now())
    store.put_job(job, {"kind": "build", "payload": {}})
    db_id = _fake_database(store, DatabaseStatus.building, build_job=job.id)
    err = error_of(client.post("/v1/jobs", json={"engine": "clip", "database": db_id, "clip": "x"}), 409)
    assert err["code"] == "database_not_ready" and "building" in err["message"]
    error_of(client.delete(f"/v1/databases/{db_id}", headers=JSON), 409, "database_building")


@pytest.mark.parametrize(
    ("request_", "status", "code", "needle"),
    [
        ({"engine": "nope", "database": "x"}, 422, "invalid_request", "unknown engine 'nope'"),
        ({"engine": "clip", "clip": "a"}, 422, "invalid_request", "names no database"),
        ({"engine": "clip", "database": "f" * 64, "clip": "a"}, 404, "not_found", "database"),
        (
            {"engine": "clip", "database": "x", "clip": "a", "start": 5, "end": 2},
            422,
            "invalid_request",
            "end",
        ),
        ({"engine": "clip", "database": "x", "clip": "a", "bogus": 1}, 422, "invalid_request", "bogus"),
        ([1, 2], 422, "invalid_request", "JSON object"),
    ],
)
def test_bad_job_requests(client: TestClient, request_: Any, status: int, code: str, needle: str) -> None:
    err = error_of(client.post("/v1/jobs", json=request_), status, code)
    assert needle in err["message"], err


def test_invalid_json_job_is_422(client: TestClient) -> None:
    err = error_of(client.post("/v1/jobs", content=b"{", headers={"content-type": "application/json"}), 422)
    assert "not valid JSON" in err["message"]


# -- jobs, events, results ------------------------------------------------------------------------
def test_clip_job_streams_to_done_and_results_download(client: TestClient, walk_db: dict[str, Any]) -> None:
    job = submit(
        client, {"engine": "clip", "database": walk_db["id"], "clip": WALK_CLIP, "start": 0, "end": 60}
    )
    # the answer is the job's status when it is written: the embedded worker may have taken the job,
    # or even finished it, by then (a busy machine)
    assert job["status"] in ("queued", "running", "done")
    assert job["kind"] == "synth" and job["engine"] == "clip"
    events = wait_events(client, job["id"])
    assert [e["type"] for e in events] == ["queued", "started", "solution", "done"]
    assert [e["id"] for e in events] == [1, 2, 3, 4]
    rid = events[-1]["data"]["result"]
    assert rid == events[2]["data"]["result"]
    info = client.get(f"/v1/jobs/{job['id']}").json()
    assert info["status"] == "done" and info["result"] == rid and info["last_event"] == 4

    bvh = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "bvh"})
    assert bvh.status_code == 200 and bvh.headers["content-type"].startswith("text/plain")
    assert f'filename="segue-{job["id"]}-{rid}.bvh"' in bvh.headers["content-disposition"]
    motion = parse_bvh(bvh.content, source="result.bvh")
    assert motion.num_frames == 60 and motion.fps == 30.0
    slow = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "bvh", "fps": 15})
    half = parse_bvh(slow.content, source="result15.bvh")
    assert half.fps == 15.0 and half.num_frames == 30
    assert np.allclose(half.root_positions, motion.root_positions[::2][:30], atol=1e-4)
    capped = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "bvh", "max_fps": 60})
    assert parse_bvh(capped.content, source="capped.bvh").fps == 30.0  # already slower: unchanged
    capped = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "bvh", "max_fps": 10})
    assert parse_bvh(capped.content, source="capped.bvh").num_frames == 20
    glb = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "glb"})
    assert glb.headers["content-type"] == "model/gltf-binary" and glb.content[:4] == b"glTF"
    frames = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "json", "result": rid}).json()
    assert {"format", "fps", "joints", "parents", "frames"} <= frames.keys() and len(frames["frames"]) == 60
    npz = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "npz", "target": "unity"})
    with np.load(io.BytesIO(npz.content), allow_pickle=False) as z:
        assert z["positions"].shape[0] == 60 and str(z["target"]) == "unity"

    report = client.get(f"/v1/jobs/{job['id']}/report").json()
    assert report["frames"] == 60 and report["engine"] == "clip"
    assert [p["frame"] for p in report["provenance"]] == list(range(60))
    assert {p["clip"] for p in report["provenance"]} == {WALK_CLIP}

    # the plain-HTTP fallback: events after an id, at once
    later = client.get(f"/v1/jobs/{job['id']}/events", params={"after": 2}).json()
    assert [e["id"] for e in later] == [3, 4]
    assert client.get(f"/v1/jobs/{job['id']}/events", params={"after": 4}).json() == []

    # the job list: newest first, filterable by status
    listed = client.get("/v1/jobs").json()
    assert listed[0]["id"] == job["id"] and walk_db["build_job"] in {j["id"] for j in listed}
    done = client.get("/v1/jobs", params={"status": "done", "limit": 1}).json()
    assert [j["id"] for j in done] == [job["id"]]
    assert client.get("/v1/jobs", params={"status": "exploded"}).status_code == 422


def test_result_errors(client: TestClient, walk_db: dict[str, Any]) -> None:
    job_id = walk_db["build_job"]  # a build job: no result
    err = error_of(client.get(f"/v1/jobs/{job_id}/result"), 404, "not_found")
    assert "without a result" in err["message"]
    error_of(client.get(f"/v1/jobs/{job_id}/result", params={"result": "r9"}), 404, "not_found")
    error_of(client.get(f"/v1/jobs/{job_id}/result", params={"format": "fbx"}), 422, "invalid_request")
    error_of(client.get(f"/v1/jobs/{job_id}/result", params={"fps": -5}), 422, "invalid_request")
    error_of(client.get(f"/v1/jobs/{job_id}/report", params={"result": "../x"}), 422, "invalid_request")
    error_of(client.get("/v1/jobs/nope/result"), 404, "not_found")
    error_of(client.get("/v1/jobs/nope"), 404, "not_found")
    error_of(client.post("/v1/jobs/nope/cancel", headers=JSON), 404, "not_found")
    error_of(client.get("/v1/nothing-here"), 404, "http_404")


def test_cancel_mid_search_keeps_best_so_far(client: TestClient, walk_db: dict[str, Any]) -> None:
    # the engine holds after 2 solutions until the cancel comes (120-s hang guard), however late
    request = {"engine": "scripted", "database": walk_db["id"], "steps": 200, "step_s": 0.02}
    job = submit(client, request | {"hold_after": 2, "budget_s": 120})
    seen: list[dict[str, Any]] = []
    with client.websocket_connect(f"/v1/jobs/{job['id']}/events") as ws:
        while True:
            event = ws.receive_json()
            seen.append(event)
            if event["type"] == "solution" and event["data"]["result"] == "r2":
                r = client.post(f"/v1/jobs/{job['id']}/cancel", headers=JSON)
                assert r.status_code == 202 and r.json()["id"] == job["id"]
            if event["type"] in ("done", "failed", "cancelled"):
                break
    last = seen[-1]
    assert last["type"] == "cancelled", seen
    solutions = [e for e in seen if e["type"] == "solution"]
    assert [e["data"]["result"] for e in solutions] == ["r1", "r2"]
    best = min(solutions, key=lambda e: e["data"]["score"])["data"]["result"]
    assert last["data"]["result"] == best
    info = client.get(f"/v1/jobs/{job['id']}").json()
    assert info["status"] == "cancelled" and info["result"] == best
    bvh = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "bvh"})
    assert bvh.status_code == 200 and parse_bvh(bvh.content).num_frames > 0
    assert (
        client.post(f"/v1/jobs/{job['id']}/cancel", headers=JSON).json()["status"] == "cancelled"
    )  # idempotent


def test_failed_job_ends_stream_with_failed(client: TestClient, walk_db: dict[str, Any]) -> None:
    job = submit(
        client, {"engine": "scripted", "database": walk_db["id"], "steps": 3, "step_s": 0, "fail_at": 1}
    )
    events = wait_events(client, job["id"])
    assert events[-1]["type"] == "failed" and "scripted failure" in events[-1]["data"]["error"]["message"]
    # a clip the database lacks is refused at submission (issue 39), not a job that fails later
    bad_clip = client.post("/v1/jobs", json={"engine": "clip", "database": walk_db["id"], "clip": "nope"})
    assert bad_clip.status_code == 422 and bad_clip.json()["error"]["code"] == "unknown_clip", bad_clip.text
    assert "no clip named 'nope'" in bad_clip.json()["error"]["message"]


def test_ws_resume_replays_only_later_events(client: TestClient, walk_db: dict[str, Any]) -> None:
    job = submit(client, {"engine": "scripted", "database": walk_db["id"], "steps": 6, "step_s": 0.03})
    first: list[dict[str, Any]] = []
    with client.websocket_connect(f"/v1/jobs/{job['id']}/events") as ws:
        while len(first) < 3:
            first.append(ws.receive_json())
    # dropped after 3 events; resume from the last id seen
    rest = wait_events(client, job["id"], after=first[-1]["id"])
    ids = [e["id"] for e in first + rest]
    assert ids == list(range(1, len(ids) + 1)), ids
    assert rest[0]["id"] == 4 and rest[-1]["type"] == "done"
    # after the end: a resume from the middle replays the tail; from the end, nothing and a clean close
    tail = wait_events(client, job["id"], after=ids[-3])
    assert [e["id"] for e in tail] == ids[-2:]
    with client.websocket_connect(f"/v1/jobs/{job['id']}/events?after={ids[-1]}") as ws:
        message = ws.receive()
        assert message["type"] == "websocket.close" and message["code"] == 1000


def test_unexpected_error_is_500_json(app: FastAPI) -> None:
    class BrokenStore:
        def list_clips(self) -> list[Any]:
            raise RuntimeError("disk on fire")

    app.dependency_overrides[app_store] = BrokenStore
    try:
        r = TestClient(app, raise_server_exceptions=False, base_url="http://localhost").get("/v1/clips")
    finally:
        app.dependency_overrides.pop(app_store)
    err = error_of(r, 500, "internal")
    assert "RuntimeError" in err["message"] and "disk on fire" not in err["message"]


def test_ws_unknown_job_closes_4404(client: TestClient) -> None:
    with (
        client.websocket_connect("/v1/jobs/" + "0" * 32 + "/events") as ws,
        pytest.raises(WebSocketDisconnect) as exc,
    ):
        ws.receive_json()
    assert exc.value.code == 4404 and "no job" in exc.value.reason


# -- auth -----------------------------------------------------------------------------------------
def test_tokens_name_principals_that_see_and_change_only_their_own(
    client: TestClient, override_settings: Callable[..., Settings]
) -> None:
    override_settings(api_tokens=("alice:ta", "bob:tb", "root:tr"), admins=("root",))
    alice, bob, root = ({"Authorization": f"Bearer {t}"} for t in ("ta", "tb", "tr"))
    # every /v1 request needs a token now, reads too
    error_of(client.get("/v1/clips"), 401, "unauthorized")
    error_of(client.get("/v1/jobs", headers={"Authorization": "Bearer wrong"}), 401, "invalid_token")
    error_of(client.post("/v1/jobs?token=ta", json={}), 401, "unauthorized")  # ?token= is for WebSockets
    assert client.get("/openapi.json").status_code == 200  # the document stays open
    clip = client.post("/v1/clips", files={"file": (WALK.name, WALK.read_bytes())}, headers=alice).json()
    spec = {"kind": "clips", "clips": [{"clip": clip["id"]}], "fps": 30}
    db = client.post("/v1/databases", json=spec, headers=alice).json()
    if db["status"] != "ready":
        with client.websocket_connect(f"/v1/jobs/{db['build_job']}/events?token=ta") as ws:
            while ws.receive_json()["type"] not in ("done", "failed", "cancelled"):
                pass
    request = {"engine": "clip", "database": db["id"], "clip": WALK_CLIP, "end": 10}
    job = client.post("/v1/jobs", json=request, headers=alice)
    assert job.status_code == 202 and job.json()["owner"] == "alice"
    job_id = job.json()["id"]
    # bob sees none of it: 404 as for things that do not exist, and empty lists
    for path in (f"/v1/clips/{clip['id']}", f"/v1/databases/{db['id']}", f"/v1/jobs/{job_id}",
                 f"/v1/jobs/{job_id}/events", f"/v1/jobs/{job_id}/report"):  # fmt: skip
        error_of(client.get(path, headers=bob), 404, "not_found")
    assert all(j["id"] != job_id for j in client.get("/v1/jobs", headers=bob).json())
    assert client.get("/v1/clips", headers=bob).json() == []
    error_of(client.post(f"/v1/jobs/{job_id}/cancel", headers=bob | JSON), 404)
    error_of(client.delete(f"/v1/databases/{db['id']}", headers=bob | JSON), 404)
    error_of(client.post("/v1/jobs", json=request, headers=bob), 404)  # not bob's database
    with (
        pytest.raises(WebSocketDenialResponse) as denied,
        client.websocket_connect(f"/v1/jobs/{job_id}/events"),
    ):
        pass
    assert denied.value.status_code == 401
    with (
        pytest.raises(WebSocketDisconnect) as closed,
        client.websocket_connect(f"/v1/jobs/{job_id}/events?token=tb") as ws,
    ):
        ws.receive_json()
    assert closed.value.code == 4404
    # alice and the admin see it
    with client.websocket_connect(f"/v1/jobs/{job_id}/events?token=ta") as ws:
        assert ws.receive_json()["type"] == "queued"
    assert client.get(f"/v1/jobs/{job_id}", headers=root).status_code == 200
    assert client.get(f"/v1/clips/{clip['id']}", headers=alice).status_code == 200
    # the same bytes uploaded by bob are bob's own hold: deleting it leaves alice's clip alone
    again = client.post("/v1/clips", files={"file": (WALK.name, WALK.read_bytes())}, headers=bob)
    assert again.status_code == 201 and again.json()["id"] == clip["id"]
    assert client.delete(f"/v1/clips/{clip['id']}", headers=bob | JSON).status_code == 204
    assert client.get(f"/v1/clips/{clip['id']}", headers=alice).status_code == 200
    error_of(client.get(f"/v1/clips/{clip['id']}", headers=bob), 404)


def test_auth_off_by_default(client: TestClient) -> None:
    assert client.app.state.settings.api_tokens == ()  # type: ignore[attr-defined]
    assert client.post("/v1/clips", params={"name": "bad.bvh"}, content=BAD_BVH.encode()).status_code == 400


# -- health, metrics, OpenAPI ---------------------------------------------------------------------
def test_healthz_and_metrics(client: TestClient, walk_db: dict[str, Any]) -> None:
    health = client.get("/healthz").json()
    assert health["ok"] is True and health["backend"]["backend"] == "embedded"
    text = client.get("/metrics").text
    assert 'segue_jobs_submitted_total{kind="build"}' in text
    assert 'segue_http_requests_total{method="GET",route="/healthz",status="200"} 1' in text
    assert "# TYPE segue_ws_connections gauge" in text and "segue_ws_connections 0" in text
    assert "segue_backend_workers 1" in text and "segue_backend_up 1" in text
    for line in text.splitlines():  # every sample line is "name{labels} number"
        if line and not line.startswith("#"):
            float(line.rsplit(" ", 1)[1])


def test_openapi_comes_from_the_schemas(client: TestClient) -> None:
    doc = client.get("/openapi.json").json()
    components = doc["components"]["schemas"]
    assert {
        "ClipInfo",
        "DatabaseInfo",
        "JobInfo",
        "JobEvent",
        "Report",
        "ErrorResponse",
        "ClipRequest",
    } <= set(components)
    assert "HTTPValidationError" not in components
    body = doc["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]["application/json"]["schema"]
    assert body == {"$ref": "#/components/schemas/JobRequest"} and "JobRequest" in components
    spec_body = doc["paths"]["/v1/databases"]["post"]["requestBody"]["content"]["application/json"]["schema"]
    assert spec_body == {"$ref": "#/components/schemas/DatabaseSpec"}
    assert "ClipsDatabaseSpec" in json.dumps(components["DatabaseSpec"])
    assert "RhythmDatabaseSpec" in json.dumps(components["DatabaseSpec"])
    links = doc["paths"]["/v1/jobs"]["post"]["responses"]["202"]["links"]
    assert links["GetJob"]["parameters"] == {"job_id": "$response.body#/id"}
    assert "multipart/form-data" in doc["paths"]["/v1/clips"]["post"]["requestBody"]["content"]
