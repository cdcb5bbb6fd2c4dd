"""Writes as plain HTTP clients send them: body-less ``DELETE`` and cancel, deleting jobs, the
``Allow`` header of a 405, and empty uploads."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from motion.samples import sample_path

from .conftest import wait_events
from .test_api import error_of, submit


def test_a_plain_delete_deletes_and_a_missing_id_is_404(client: TestClient) -> None:
    """``curl -X DELETE``: no body, no content type."""
    path = sample_path("start-walk-stop")
    clip = client.post("/v1/clips", files={"file": (path.name, path.read_bytes())}).json()
    r = client.delete(f"/v1/clips/{clip['id']}")
    assert r.status_code == 204, r.text
    error_of(client.get(f"/v1/clips/{clip['id']}"), 404, "not_found")
    error_of(client.delete(f"/v1/clips/{clip['id']}"), 404, "not_found")
    for kind in ("clips", "files", "databases", "jobs"):
        error_of(client.delete(f"/v1/{kind}/nope"), 404, "not_found")


@pytest.mark.parametrize("content_type", ["text/plain", "application/x-www-form-urlencoded", ""])
def test_a_body_that_is_not_json_is_still_415(client: TestClient, content_type: str) -> None:
    file = client.post("/v1/files", params={"name": "keep.txt"}, content=b"keep me").json()
    headers = {"content-type": content_type} if content_type else {}
    r = client.request("DELETE", f"/v1/files/{file['id']}", content=b"x=1", headers=headers)
    error_of(r, 415, "unsupported_media_type")
    assert client.get(f"/v1/files/{file['id']}").status_code == 200


def test_cancel_needs_no_body(client: TestClient, walk_db: dict[str, Any]) -> None:
    job = submit(client, {"engine": "scripted", "database": walk_db["id"], "steps": 500, "step_s": 0.05})
    r = client.post(f"/v1/jobs/{job['id']}/cancel")
    assert r.status_code == 202, r.text
    assert wait_events(client, job["id"])[-1]["type"] == "cancelled"
    error_of(client.post("/v1/jobs/nope/cancel"), 404, "not_found")


def test_a_finished_job_is_deleted_a_running_one_is_409(client: TestClient, walk_db: dict[str, Any]) -> None:
    running = submit(client, {"engine": "scripted", "database": walk_db["id"], "steps": 500, "step_s": 0.05})
    err = error_of(client.delete(f"/v1/jobs/{running['id']}"), 409, "job_not_finished")
    assert "cancel it first" in err["message"] and err["details"]["job"] == running["id"]
    client.post(f"/v1/jobs/{running['id']}/cancel")
    assert wait_events(client, running["id"])[-1]["type"] == "cancelled"
    assert client.delete(f"/v1/jobs/{running['id']}").status_code == 204

    done = submit(client, {"engine": "scripted", "database": walk_db["id"], "steps": 2, "step_s": 0})
    assert wait_events(client, done["id"])[-1]["type"] == "done"
    assert client.get(f"/v1/jobs/{done['id']}/result").status_code == 200
    assert client.delete(f"/v1/jobs/{done['id']}").status_code == 204
    for path in ("", "/result", "/report", "/events"):
        error_of(client.get(f"/v1/jobs/{done['id']}{path}"), 404, "not_found")
    assert done["id"] not in {j["id"] for j in client.get("/v1/jobs").json()}
    error_of(client.delete(f"/v1/jobs/{done['id']}"), 404, "not_found")
    # the database the jobs ran on stays
    assert client.get(f"/v1/databases/{walk_db['id']}").json()["status"] == "ready"


@pytest.mark.parametrize(
    ("method", "path", "allowed"),
    [
        ("PUT", "/v1/jobs/abc", ["GET", "DELETE"]),
        ("PATCH", "/v1/databases/abc", ["GET", "DELETE"]),
        ("DELETE", "/v1/jobs", ["GET", "POST"]),
        ("PUT", "/v1/clips", ["GET", "POST"]),
        ("GET", "/v1/jobs/abc/cancel", ["POST"]),
    ],
)
def test_405_names_every_allowed_method(
    client: TestClient, method: str, path: str, allowed: list[str]
) -> None:
    r = client.request(method, path)
    body = error_of(r, 405, "method_not_allowed")
    assert sorted(r.headers["allow"].split(", ")) == sorted(allowed)
    assert sorted(body["details"]["allowed"]) == sorted(allowed) and method in body["message"]


@pytest.mark.parametrize("route", ["/v1/clips", "/v1/files"])
def test_an_empty_upload_is_refused(client: TestClient, route: str) -> None:
    before = len(client.get(route).json())
    err = error_of(client.post(route, params={"name": "empty.bvh"}, content=b""), 422, "empty_upload")
    assert "'empty.bvh' is empty" in err["message"]
    err = error_of(client.post(route, files={"file": ("empty.mid", b"")}), 422, "empty_upload")
    assert "'empty.mid' is empty" in err["message"]
    assert len(client.get(route).json()) == before
