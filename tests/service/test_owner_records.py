"""Per-principal names over shared bytes: a principal uploading another's exact bytes, or posting
another's database spec, sees its own name, upload time and build job, never the other's; stores
written before records were (owners as a plain list) still read, with the shared info."""

from __future__ import annotations

import io
import json
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient

from motion.bvh import write_bvh
from tests.motion.synthetic import walking_biped
from workers.settings import Settings

from .test_api_bounded import _bvh

JSON = {"Content-Type": "application/json"}


def _principals(override_settings: Callable[..., Settings]) -> tuple[dict[str, str], dict[str, str]]:
    # principals of their own: other tests' alice and bob must not hold what these leave behind
    override_settings(api_tokens=("carol:tc", "dave:td", "root:tr"), admins=("root",))
    return {"Authorization": "Bearer tc"}, {"Authorization": "Bearer td"}


def _upload(client: TestClient, route: str, name: str, data: bytes, who: dict[str, str]) -> Any:
    r = client.post(route, files={"file": (name, data)}, headers=who)
    assert r.status_code in (200, 201), r.text
    return r


def test_another_principals_bytes_keep_your_name_and_time(
    client: TestClient, override_settings: Callable[..., Settings]
) -> None:
    alice, bob = _principals(override_settings)
    data = _bvh(1.2345)
    mine = _upload(client, "/v1/clips", "alice-walk.bvh", data, alice).json()
    time.sleep(0.01)  # distinct upload times (the assertion is on their order, not on a duration)
    r = _upload(client, "/v1/clips", "bob-walk.bvh", data, bob)
    theirs = r.json()
    assert r.status_code == 201  # new to bob, although the bytes are stored
    assert theirs["id"] == mine["id"]
    assert theirs["name"] == "bob-walk.bvh" and theirs["created_at"] > mine["created_at"]
    for who, name, created in ((alice, "alice-walk.bvh", mine), (bob, "bob-walk.bvh", theirs)):
        got = client.get(f"/v1/clips/{mine['id']}", headers=who).json()
        assert (got["name"], got["created_at"]) == (name, created["created_at"])
        listed = [c for c in client.get("/v1/clips", headers=who).json() if c["id"] == mine["id"]]
        assert [c["name"] for c in listed] == [name]
        assert client.get(f"/v1/clips/{name}", headers=who).json()["id"] == mine["id"]  # by its own name
    assert client.get("/v1/clips/bob-walk.bvh", headers=alice).status_code == 404  # not alice's name
    # a second upload by bob is 200 and keeps his first name
    again = _upload(client, "/v1/clips", "renamed.bvh", data, bob)
    assert again.status_code == 200 and again.json()["name"] == "bob-walk.bvh"


def test_files_are_named_per_principal(
    client: TestClient, override_settings: Callable[..., Settings]
) -> None:
    alice, bob = _principals(override_settings)
    data = b"MThd per-principal file test " + str(time.time_ns()).encode()
    mine = _upload(client, "/v1/files", "alice.mid", data, alice).json()
    theirs = _upload(client, "/v1/files", "bob.mid", data, bob).json()
    assert theirs["id"] == mine["id"] and theirs["name"] == "bob.mid"
    assert client.get(f"/v1/files/{mine['id']}", headers=alice).json()["name"] == "alice.mid"
    assert client.get(f"/v1/files/{mine['id']}", headers=bob).json()["name"] == "bob.mid"
    assert [f["name"] for f in client.get("/v1/files", headers=bob).json() if f["id"] == mine["id"]] == [
        "bob.mid"
    ]


def test_a_spec_posted_by_another_principal_gets_its_own_name_and_no_foreign_build_job(
    client: TestClient, override_settings: Callable[..., Settings]
) -> None:
    alice, bob = _principals(override_settings)
    # its own bytes (other tests' principals hold the bundled samples), a walk whose graph builds:
    # bob's post finds alice's database queued, building or ready (200) whenever it comes; with a
    # clip whose build fails, a build that failed before bob's post was rebuilt for him (202)
    buf = io.StringIO()
    write_bvh(walking_biped(90, seed=15678), buf)
    data = buf.getvalue().encode()
    clip = _upload(client, "/v1/clips", "db-clip.bvh", data, alice).json()
    _upload(client, "/v1/clips", "db-clip.bvh", data, bob)
    clips = [{"clip": clip["id"], "name": "owners-test-clip", "units": "m"}]
    first = client.post(
        "/v1/databases", json={"kind": "graph", "name": "alice-db", "clips": clips}, headers=alice
    )
    assert first.status_code == 202, first.text
    db = first.json()
    second = client.post(
        "/v1/databases", json={"kind": "graph", "name": "bob-db", "clips": clips}, headers=bob
    )
    assert second.status_code == 200, second.text
    seen = second.json()
    assert seen["id"] == db["id"] and seen["name"] == "bob-db"
    assert seen["build_job"] is None  # alice's build is hers (bob cannot read it anyway)
    assert client.get(f"/v1/databases/{db['id']}", headers=bob).json()["name"] == "bob-db"
    got = client.get(f"/v1/databases/{db['id']}", headers=alice).json()
    assert (got["name"], got["build_job"]) == ("alice-db", db["build_job"])


def test_owners_stored_as_a_plain_list_still_read(
    client: TestClient, override_settings: Callable[..., Settings], api_settings: Settings
) -> None:
    alice, bob = _principals(override_settings)
    data = _bvh(1.3456)
    clip = _upload(client, "/v1/clips", "legacy.bvh", data, alice).json()
    owners = Path(api_settings.data_dir) / "clips" / f"{clip['id']}.owners"
    owners.write_text(json.dumps(["carol"]))  # as written before per-principal records
    got = client.get(f"/v1/clips/{clip['id']}", headers=alice).json()
    assert got["name"] == "legacy.bvh"  # the shared info
    theirs = _upload(client, "/v1/clips", "bob-legacy.bvh", data, bob).json()
    assert theirs["name"] == "bob-legacy.bvh"
    assert client.get(f"/v1/clips/{clip['id']}", headers=alice).json()["name"] == "legacy.bvh"
    assert client.delete(f"/v1/clips/{clip['id']}", headers=alice | JSON).status_code == 204
    assert client.get(f"/v1/clips/{clip['id']}", headers=bob).json()["name"] == "bob-legacy.bvh"


def test_a_delete_racing_another_principals_upload_over_http_keeps_its_clip(
    client: TestClient, override_settings: Callable[..., Settings]
) -> None:
    """The measured failure: alice's DELETE racing bob's upload of the same bytes lost bob's clip."""
    alice, bob = _principals(override_settings)
    data = _bvh(1.4567)
    for trial in range(25):
        clip = _upload(client, "/v1/clips", "a.bvh", data, alice).json()
        answers = _delete_racing_upload(client, clip["id"], data, alice, bob)
        assert answers == {"delete": 204, "upload": 201}, (trial, answers)
        got = client.get(f"/v1/clips/{clip['id']}/bvh", headers=bob)
        assert got.status_code == 200 and got.content == data, trial
        assert client.get(f"/v1/clips/{clip['id']}", headers=bob).json()["name"] == "b.bvh"
        assert client.get(f"/v1/clips/{clip['id']}", headers=alice).status_code == 404
        assert client.delete(f"/v1/clips/{clip['id']}", headers=bob | JSON).status_code == 204


def _delete_racing_upload(
    client: TestClient, clip_id: str, data: bytes, alice: dict[str, str], bob: dict[str, str]
) -> dict[str, int]:
    """Alice's DELETE and bob's upload of the same bytes, released together; their status codes."""
    barrier = threading.Barrier(2)
    answers: dict[str, int] = {}

    def delete() -> None:
        barrier.wait(120)
        answers["delete"] = client.delete(f"/v1/clips/{clip_id}", headers=alice | JSON).status_code

    def upload() -> None:
        barrier.wait(120)
        answers["upload"] = client.post("/v1/clips", files={"file": ("b.bvh", data)}, headers=bob).status_code

    threads = [threading.Thread(target=delete), threading.Thread(target=upload)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    return answers
