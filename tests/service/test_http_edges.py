"""The HTTP API's first-hour edges: a result asked for too early, long polls, label ranges past a
clip's end, bundled samples named in specs and requests, a database's summary, a clip's bytes."""

from __future__ import annotations

import gzip
import time
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from motion.samples import sample_path
from tests.motion.bvh_helpers import under_static_root

from .conftest import WALK_CLIP, wait_events
from .test_api import JSON, error_of, submit


def _ready(client: TestClient, spec: dict[str, Any]) -> dict[str, Any]:
    r = client.post("/v1/databases", json=spec)
    assert r.status_code in (200, 202), r.text
    db = r.json()
    if db["status"] != "ready":
        assert wait_events(client, db["build_job"])[-1]["type"] == "done"
    db = client.get(f"/v1/databases/{db['id']}").json()
    assert db["status"] == "ready", db
    return dict(db)


def test_a_result_asked_for_before_the_first_solution_is_409_with_the_status(
    client: TestClient, walk_db: dict[str, Any], tmp_path: Path
) -> None:
    # the engine waits for a file before its first step, so no solution exists until the test
    # makes it, however loaded the machine
    go = tmp_path / "go"
    request = {"engine": "scripted", "database": walk_db["id"], "steps": 1, "budget_s": 120}
    job = submit(client, request | {"go_file": str(go)})
    for path in ("result", "report"):
        err = error_of(client.get(f"/v1/jobs/{job['id']}/{path}"), 409, "result_not_ready")
        assert err["details"]["status"] in ("queued", "running") and "no result yet" in err["message"]
    go.touch()
    assert wait_events(client, job["id"])[-1]["type"] == "done"
    assert client.get(f"/v1/jobs/{job['id']}/result").status_code == 200
    # a job that ended without a result is still a 404 (there is nothing to wait for)
    err = error_of(client.get(f"/v1/jobs/{walk_db['build_job']}/result"), 404, "not_found")
    assert "finished without a result" in err["message"]


def test_events_wait_returns_at_the_end_with_every_event(client: TestClient, walk_db: dict[str, Any]) -> None:
    """``wait=S`` holds the answer until the job ends (or S seconds): every event in between, not
    just the first new one."""
    job = submit(client, {"engine": "scripted", "database": walk_db["id"], "steps": 4, "step_s": 0.1})
    # 60 s (the most a long poll may ask): a hang guard, the job's 4 steps take 0.4 s
    got = client.get(f"/v1/jobs/{job['id']}/events", params={"after": 0, "wait": 60}).json()
    assert [e["id"] for e in got] == list(range(1, len(got) + 1))
    assert got[-1]["type"] == "done" and sum(e["type"] == "solution" for e in got) == 4
    # the job has ended: nothing after its last event, at once
    after_end = {"after": got[-1]["id"], "wait": 30}
    assert client.get(f"/v1/jobs/{job['id']}/events", params=after_end).json() == []


def test_events_wait_waits_for_the_timeout_when_nothing_is_new(
    client: TestClient, walk_db: dict[str, Any], tmp_path: Path
) -> None:
    # the engine waits for a file that never comes (until the cancel, or its 120-s budget), so the
    # wait cannot end with an event, only at its timeout, however loaded the machine
    never = str(tmp_path / "never")
    request = {"engine": "scripted", "database": walk_db["id"], "steps": 2, "go_file": never, "budget_s": 120}
    job = submit(client, request)
    with client.websocket_connect(f"/v1/jobs/{job['id']}/events") as ws:
        assert [ws.receive_json()["type"] for _ in range(2)] == ["queued", "started"]
    t0 = time.monotonic()
    got = client.get(f"/v1/jobs/{job['id']}/events", params={"after": 2, "wait": 0.4}).json()
    assert got == [] and time.monotonic() - t0 >= 0.4
    client.post(f"/v1/jobs/{job['id']}/cancel", headers=JSON)
    assert wait_events(client, job["id"])[-1]["type"] == "cancelled"


def test_a_label_range_past_the_clips_end_is_refused(client: TestClient, walk_clip: dict[str, Any]) -> None:
    """The walk has 80 frames at 30 fps: a label to frame 81 is a 422 naming the clip and its length
    (before this, it was clamped silently)."""
    spec = {
        "kind": "annotated",
        "clips": [{"bvh": walk_clip["name"], "labels": [{"label": "walk", "start": 10, "end": 81}]}],
    }
    err = error_of(client.post("/v1/databases", json=spec), 422, "invalid_request")
    assert "labels[0] 'walk' [10, 81) ends after the clip" in err["message"]
    assert "80 frames at 30 fps" in err["message"] and WALK_CLIP in err["message"]
    spec["clips"][0]["labels"][0]["end"] = 80  # the last frame is 79: [10, 80) is fine
    assert client.post("/v1/databases", json=spec).status_code in (200, 202)


def test_samples_in_specs_and_requests(client: TestClient) -> None:
    """``sample:NAME`` works over HTTP as in a spec file: the bundled clip is stored like an upload
    (and listed as yours), named NAME in the database; a request's input file may be one too."""
    db = _ready(client, {"kind": "clips", "clips": [{"bvh": "sample:run-09-01"}], "fps": 30})
    assert db["clips"] == ["run-09-01"] and db["frames"] == 38
    assert "09_01_run_daz_30fps.bvh.gz" in [c["name"] for c in client.get("/v1/clips").json()]
    job = submit(
        client,
        {"engine": "scripted", "database": db["id"], "steps": 1, "step_s": 0, "input": "sample:song"},
    )
    events = wait_events(client, job["id"])
    assert events[-1]["type"] == "done", events[-1]
    solution = next(e for e in events if e["type"] == "solution")
    assert solution["data"]["terms"]["input_bytes"] == len(sample_path("song").read_bytes())
    assert client.get(f"/v1/jobs/{job['id']}").json()["status"] == "done"
    nope = {"kind": "clips", "clips": [{"bvh": "sample:nope"}]}
    assert "no bundled sample 'nope'" in error_of(client.post("/v1/databases", json=nope), 404)["message"]
    bad = {"engine": "scripted", "database": db["id"], "input": "sample:nope"}
    err = error_of(client.post("/v1/jobs", json=bad), 422, "input_not_found")
    assert "no bundled sample" in err["message"]


def test_database_summary_for_clients_that_did_not_build_it(client: TestClient) -> None:
    db = _ready(
        client,
        {
            "kind": "control",
            "pairs": [{"control": "sample:salsa-leader-02", "target": "sample:salsa-follower-02"}],
        },
    )
    summary = db["summary"]
    assert summary["kind"] == "control" and summary["units"] == "m" and summary["control"] == "motion"
    roles = {c["name"]: c["role"] for c in summary["clips"]}
    assert roles == {"salsa-follower-02": "target", "salsa-leader-02": "control"}
    assert summary["skeleton"]["hips"] == "hip" and summary["skeleton"]["static_root"] is False
    assert summary["skeleton"]["joints"][0] == "hip" and summary["skeleton"]["parents"][0] == -1
    assert {c["source_units"] for c in summary["clips"]} == {"cmu-scaled"}  # the sample catalogue's unit
    walks = _ready(client, {"kind": "control", "pairs": [{"target": "sample:walk-10-04"}]})
    assert walks["summary"]["control"] == "path"
    listed = {d["id"]: d for d in client.get("/v1/databases").json()}
    assert listed[walks["id"]]["summary"] == walks["summary"]

    labelled = _ready(
        client,
        {
            "kind": "annotated",
            "gammas": [1.0],
            "clips": [
                {"bvh": "sample:run-09-01", "labels": [{"label": "run", "start": 1, "end": 38}]},
                {"bvh": "sample:walk-10-04", "labels": [{"label": "walk", "start": 1, "end": 138}]},
                {"bvh": "sample:run-09-02"},
            ],
        },
    )
    s = labelled["summary"]
    assert s["labels"] == ["run", "walk"]
    assert s["clips"][0]["labels"] == [{"label": "run", "start": 1, "end": 38, "value": 1}]
    assert [c["frames"] for c in s["clips"]] == [38, 138, 33]


@pytest.mark.parametrize("sample", ["walk", "run-09-02"])
def test_a_clip_downloads_as_uploaded(client: TestClient, sample: str) -> None:
    path = sample_path(sample)
    info = client.post("/v1/clips", files={"file": (path.name, path.read_bytes())}).json()
    r = client.get(f"/v1/clips/{info['id']}/bvh")
    assert r.status_code == 200 and r.content == path.read_bytes()
    assert path.name in r.headers["content-disposition"]
    error_of(client.get("/v1/clips/" + "0" * 64 + "/bvh"), 404, "not_found")


def test_summary_names_the_hips_of_a_rig_with_a_static_root(client: TestClient) -> None:
    """A Bandai-Namco-like rig (joint 0 a static ground node): the summary's hips are the joint
    that carries the body, not joint 0."""
    text = under_static_root(gzip.decompress(sample_path("run-09-04").read_bytes()).decode())
    r = client.post("/v1/clips", files={"file": ("static-root.bvh", text.encode())})
    assert r.status_code in (200, 201), r.text
    db = _ready(client, {"kind": "clips", "clips": [{"bvh": "static-root.bvh"}], "fps": 30})
    skeleton = db["summary"]["skeleton"]
    assert skeleton["joints"][:2] == ["joint_Root", "hip"]
    assert skeleton["static_root"] is True and skeleton["hips"] == "hip"
