"""The annotation engine's correction loop over HTTP: read a clip's labels, correct them, rebuild."""

from __future__ import annotations

import itertools
from typing import Any

import pytest
from fastapi.testclient import TestClient

from motion.samples import sample_path

from .conftest import wait_events


def _ready(client: TestClient, response: Any) -> dict[str, Any]:
    assert response.status_code in (200, 202), response.text
    db = response.json()
    if db["status"] != "ready":
        events = wait_events(client, db["build_job"])
        assert events[-1]["type"] == "done", events[-1]
    db = client.get(f"/v1/databases/{db['id']}").json()
    assert db["status"] == "ready", db
    return dict(db)


def upload_salsa(client: TestClient) -> list[str]:
    """Upload the bundled salsa leader and follower; their clip names."""
    names = []
    for sample in ("salsa-leader", "salsa-follower"):
        path = sample_path(sample)
        r = client.post("/v1/clips", files={"file": (path.name, path.read_bytes())})
        assert r.status_code in (200, 201), r.text
        names.append(r.json()["name"])
    return names


@pytest.fixture(scope="module")
def annotated_db(client: TestClient) -> dict[str, Any]:
    names = upload_salsa(client)
    spec = {
        "kind": "annotated",
        "gammas": [1.0],
        "clips": [
            {"bvh": names[0], "name": "lead", "labels": [{"label": "walk", "start": 0, "end": 60}]},
            {"bvh": names[1], "name": "follower"},
        ],
    }
    return _ready(client, client.post("/v1/databases", json=spec))


def test_labels_of_a_clip_are_ranges_covering_it(client: TestClient, annotated_db: dict[str, Any]) -> None:
    r = client.get(f"/v1/databases/{annotated_db['id']}/labels", params={"clip": "follower"})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["clip"] == "follower" and body["frames"] > 0
    walk = sorted((x["start"], x["end"]) for x in body["labels"] if x["label"] == "walk")
    assert walk[0][0] == 0 and walk[-1][1] == body["frames"]
    assert all(a[1] == b[0] for a, b in itertools.pairwise(walk))  # contiguous, no gaps
    assert {x["value"] for x in body["labels"]} <= {1, -1}


def test_label_errors(client: TestClient, annotated_db: dict[str, Any]) -> None:
    db = annotated_db["id"]
    missing = client.get(f"/v1/databases/{db}/labels", params={"clip": "nope"})
    assert missing.status_code == 404 and "nope" in missing.json()["error"]["message"]
    bad = client.get(f"/v1/databases/{db}/labels", params={"clip": "follower", "start": 10_000})
    assert bad.status_code == 422
    empty = client.post(f"/v1/databases/{db}/corrections", json=[])
    assert empty.status_code == 422
    wrong = client.post(
        f"/v1/databases/{db}/corrections", json=[{"clip": "ghost", "start": 0, "end": 5, "label": "x"}]
    )
    assert wrong.status_code == 422 and "ghost" in wrong.json()["error"]["message"]


def test_a_correction_builds_a_new_database_with_the_label(
    client: TestClient, annotated_db: dict[str, Any]
) -> None:
    db = annotated_db["id"]
    fixes = [
        {"clip": "follower", "start": 0, "end": 20, "action": "accept"},
        {"clip": "follower", "start": 20, "end": 50, "label": "walk", "value": -1},
    ]
    new = _ready(client, client.post(f"/v1/databases/{db}/corrections", json=fixes))
    assert new["id"] != db and new["kind"] == "annotated"
    labels = client.get(
        f"/v1/databases/{new['id']}/labels", params={"clip": "follower", "start": 20, "end": 50}
    ).json()
    walk = [x for x in labels["labels"] if x["label"] == "walk"]
    assert walk == [{"label": "walk", "start": 20, "end": 50, "value": -1}]
    again = client.post(f"/v1/databases/{db}/corrections", json=fixes)
    assert again.status_code == 200 and again.json()["id"] == new["id"]  # same content address


def test_corrections_count_against_the_job_quota(
    client: TestClient, annotated_db: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    quota = client.app.state.job_quota  # type: ignore[attr-defined]
    monkeypatch.setattr(quota, "limit", 0)  # every principal is at its limit of unfinished jobs
    fixes = [{"clip": "follower", "start": 3, "end": 9, "label": "turn", "value": 1}]
    r = client.post(f"/v1/databases/{annotated_db['id']}/corrections", json=fixes)
    assert r.status_code == 429 and r.json()["error"]["code"] == "too_many_jobs", r.text
    monkeypatch.setattr(quota, "limit", 1_000)
    built = client.post(f"/v1/databases/{annotated_db['id']}/corrections", json=fixes)
    assert built.status_code == 202, built.text
    assert built.json()["build_job"] in set().union(*quota._open.values())
    _ready(client, built)


def test_a_mirrored_database_names_and_labels_its_mirror_images(client: TestClient) -> None:
    names = upload_salsa(client)
    spec = {
        "kind": "annotated",
        "gammas": [1.0],
        "mirror": True,
        "clips": [
            {"bvh": names[0], "name": "lead", "labels": [{"label": "spin-left", "start": 0, "end": 60}]},
            {"bvh": names[1], "name": "follower"},
        ],
    }
    db = _ready(client, client.post("/v1/databases", json=spec))
    summary = db["summary"]
    assert [c["name"] for c in summary["clips"]] == ["lead", "follower", "lead (mirror)", "follower (mirror)"]
    assert summary["clips"][2]["labels"] == [{"label": "spin-right", "start": 0, "end": 60, "value": 1}]
    assert summary["labels"] == ["spin-left", "spin-right"]
    r = client.get(f"/v1/databases/{db['id']}/labels", params={"clip": "lead (mirror)", "end": 60})
    assert r.status_code == 200, r.text
    assert {(x["label"], x["value"]) for x in r.json()["labels"]} == {("spin-right", 1), ("spin-left", -1)}
    fixes = [{"clip": "follower (mirror)", "start": 0, "end": 30, "label": "spin-right", "value": 1}]
    new = _ready(client, client.post(f"/v1/databases/{db['id']}/corrections", json=fixes))
    follower = next(c for c in new["summary"]["clips"] if c["name"] == "follower")
    assert follower["labels"] == [{"label": "spin-left", "start": 0, "end": 30, "value": 1}]
    r = client.get(f"/v1/databases/{new['id']}/labels", params={"clip": "follower (mirror)", "end": 30})
    assert ("spin-right", 1) in {(x["label"], x["value"]) for x in r.json()["labels"]}


def test_a_timeline_label_outside_the_vocabulary_is_refused_at_submission(
    client: TestClient, annotated_db: dict[str, Any]
) -> None:
    # Regression (issue 39): an unknown label was accepted (202) and the job failed later.
    db = annotated_db["id"]
    request = {"engine": "annotations", "database": db, "frames": 60, "passes": 1}
    r = client.post("/v1/jobs", json={**request, "timeline": [{"label": "dance", "start": 0, "end": 60}]})
    assert r.status_code == 422, r.text
    err = r.json()["error"]
    assert err["code"] == "unknown_label"
    assert "timeline[0]: label 'dance' is not in the database's vocabulary ('walk')" in err["message"]
    assert err["details"]["labels"] == ["walk"]
    # a frame constraint on a clip the database lacks, or past a clip's end
    for constraint, says in (
        ({"frame": 0, "clip": "ghost", "clip_frame": 0}, "no clip named 'ghost'"),
        ({"frame": 0, "clip": "lead", "clip_frame": 10**6}, "past the end of clip 'lead'"),
    ):
        r = client.post("/v1/jobs", json={**request, "frame_constraints": [constraint]})
        assert r.status_code == 422 and r.json()["error"]["code"] == "unknown_clip", r.text
        assert says in r.json()["error"]["message"]
