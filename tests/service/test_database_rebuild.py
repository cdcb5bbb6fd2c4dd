"""A database whose build failed says why, and posting its spec again builds it again."""

from __future__ import annotations

import gzip

from fastapi.testclient import TestClient

from service.settings import Settings

from .conftest import WALK, wait_events


def test_a_failed_build_is_failed_with_its_reason_and_reposting_rebuilds(
    client: TestClient, api_settings: Settings
) -> None:
    text = gzip.decompress(WALK.read_bytes())  # bytes no other test uploads
    clip = client.post("/v1/clips", files={"file": ("rebuild_walk.bvh", text)}).json()
    stored = api_settings.data_dir / "clips" / f"{clip['id']}.bvh"
    hidden = stored.with_suffix(".hidden")
    stored.rename(hidden)  # the build cannot read the clip: it fails
    spec = {"kind": "clips", "clips": [{"clip": clip["id"]}], "fps": 24}
    first = client.post("/v1/databases", json=spec)
    assert first.status_code == 202, first.text
    assert wait_events(client, first.json()["build_job"])[-1]["type"] == "failed"
    failed = client.get(f"/v1/databases/{first.json()['id']}").json()
    assert failed["status"] == "failed" and "no clip" in failed["error"]

    hidden.rename(stored)
    again = client.post("/v1/databases", json=spec)
    assert again.status_code == 202, again.text
    assert again.json()["id"] == failed["id"] and again.json()["build_job"] != failed["build_job"]
    assert wait_events(client, again.json()["build_job"])[-1]["type"] == "done"
    assert client.get(f"/v1/databases/{failed['id']}").json()["status"] == "ready"
