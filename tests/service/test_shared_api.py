"""Several characters with shared constraints over HTTP: a job on the bundled walks comes back
with a combined skeleton and the shared entries in its report; bad shared constraints are 422s at
submission (unknown character, frame past the length, unknown joint)."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from .conftest import wait_events
from .test_http_edges import _ready

WALKS = ("walk-05-01", "walk-10-04", "walk-12-02", "walk")


@pytest.fixture(scope="module")
def walks_db(client: TestClient) -> dict[str, Any]:
    return _ready(client, {"kind": "graph", "clips": [{"bvh": f"sample:{c}", "name": c} for c in WALKS]})


def request(db: dict[str, Any], shared: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "engine": "graph",
        "database": db["id"],
        "frames": 90,
        "seed": 1,
        "rounds": 5,
        "coupling_rounds": 1,
        "budget_s": 60,
        "characters": [
            {"constraints": [{"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 90}]},
            {"constraints": [{"type": "body", "frame": 0, "position": [4.0, 0.8], "heading_deg": -90}]},
        ],
        "shared": shared,
    }


def test_a_job_with_shared_constraints_reports_them(client: TestClient, walks_db: dict[str, Any]) -> None:
    shared = [
        {
            "type": "meet",
            "frame": 45,
            "a": {"character": 0, "joint": "rHand"},
            "b": {"character": 1, "joint": "rHand"},
        },
        {"type": "apart", "a": {"character": 0}, "b": {"character": 1}, "min_m": 0.5, "end": 35},
    ]
    r = client.post("/v1/jobs", json=request(walks_db, shared))
    assert r.status_code in (200, 201, 202), r.text
    job = r.json()
    assert wait_events(client, job["id"])[-1]["type"] == "done"
    report = client.get(f"/v1/jobs/{job['id']}/report").json()
    errors = report["constraint_errors"]
    assert {"shared[0]", "shared[1]", "c0.body[0]", "c1.body[0]"} <= set(errors)
    assert errors["shared[0]"]["a"] == "c0.rHand" and "distance_cm" in errors["shared[0]"]
    assert errors["shared[1]"]["min_distance_cm"] > 0
    bvh = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "bvh"}).text
    assert "ROOT world" in bvh and "c0_rHand" in bvh and "c1_rHand" in bvh


@pytest.mark.parametrize(
    ("shared", "code", "words"),
    [
        (
            {"type": "meet", "frame": 5, "a": {"character": 0}, "b": {"character": 3}},
            "invalid_request",
            "character 3",
        ),
        (
            {"type": "meet", "frame": 90, "a": {"character": 0}, "b": {"character": 1}},
            "invalid_request",
            "past",
        ),
        (
            {"type": "meet", "frame": 5, "a": {"character": 0, "joint": "rPaw"}, "b": {"character": 1}},
            "unknown_joint",
            "shared[0].a: 'rPaw'",
        ),
    ],
)
def test_bad_shared_constraints_are_422(
    client: TestClient, walks_db: dict[str, Any], shared: dict[str, Any], code: str, words: str
) -> None:
    r = client.post("/v1/jobs", json=request(walks_db, [shared]))
    assert r.status_code == 422, r.text
    body = r.json()["error"]
    assert words in body["message"] or words in str(body.get("details")), body
    if code == "unknown_joint":
        assert body["code"] == code and "rHand" in body["details"]["joints"]
        # where it was asked for first, then the joint, then the joints there are
        assert body["message"].startswith(
            "shared[0].a: the database's skeleton has no joint named 'rPaw' (joints: "
        ), body["message"]
