"""The API on an object store: everything durable goes to the S3-protocol server (moto), and the
API's data directory holds nothing but the engine processes' cache."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from motion.bvh import parse_bvh
from service.app import create_app
from service.settings import Settings
from workers.store import Store

from .conftest import PLUGINS, WALK, WALK_CLIP, ready_database, wait_events


def test_upload_build_synth_and_fetch_through_an_object_store(s3_url: str, tmp_path: Path) -> None:
    data = tmp_path / "api-host"
    settings = Settings(
        data_dir=data,
        store_url=s3_url,
        workers=1,
        engine_plugins=PLUGINS,
        allowed_hosts=("localhost", "testserver"),
        job_grace_s=600.0,
    )
    with TestClient(create_app(settings), base_url="http://localhost") as client:
        clip = client.post("/v1/clips", files={"file": (WALK.name, WALK.read_bytes())}).json()
        db = ready_database(client, {"kind": "clips", "clips": [{"bvh": clip["name"]}], "fps": 30})
        request = {"engine": "clip", "database": db["id"], "clip": WALK_CLIP, "start": 0, "end": 40}
        r = client.post("/v1/jobs", json=request)
        assert r.status_code == 202, r.text
        events = wait_events(client, r.json()["id"])
        assert events[-1]["type"] == "done", events
        job = r.json()["id"]
        bvh = client.get(f"/v1/jobs/{job}/result", params={"format": "bvh"})
        assert parse_bvh(bvh.content, source="r.bvh").num_frames == 40
        assert client.get(f"/v1/jobs/{job}/report").json()["frames"] == 40
        glb = client.get(f"/v1/jobs/{job}/result", params={"format": "glb"})
        assert glb.content[:4] == b"glTF"
    # every durable thing is in the bucket...
    store = Store(s3_url, tmp_path / "elsewhere")
    assert store.clip_info(clip["id"]).frames == clip["frames"]
    assert store.database_info(db["id"]).status == "ready" and store.has_database_arrays(db["id"])
    assert store.job_info(job).status == "done" and len(store.events(job)) == len(events)
    # ...and the API host's directory is a cache only
    assert {p.name for p in data.iterdir()} <= {"cache"}
