"""Hostile requests (issue 17): each is refused with a clear 4xx at submission, and nothing stored is
touched. One test per finding: non-finite numbers, deep nesting, body limits, cross-site bodies,
Host and Origin, work budgets, units of a re-upload, NUL characters, absurd resampling, 500s."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import pytest
from fastapi.testclient import TestClient
from starlette.testclient import WebSocketDenialResponse

from service.settings import Settings

from .conftest import WALK, WALK_CLIP
from .test_api import error_of


def _job(db: str, **extra: Any) -> dict[str, Any]:
    return {"engine": "clip", "database": db, "clip": WALK_CLIP, "end": 10, **extra}


def _jobs_count(client: TestClient) -> int:
    return len(client.get("/v1/jobs", params={"limit": 1000}).json())


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_non_finite_numbers_are_refused(client: TestClient, walk_db: dict[str, Any], literal: str) -> None:
    before = _jobs_count(client)
    raw = json.dumps(_job(walk_db["id"], position=[0.0, 0.0])).replace("[0.0, 0.0]", f"[{literal}, 0]")
    r = client.post("/v1/jobs", content=raw, headers={"content-type": "application/json"})
    error_of(r, 422, "invalid_request")
    spec = '{"kind": "clips", "clips": [{"clip": "x"}], "fps": ' + literal + "}"
    error_of(client.post("/v1/databases", content=spec, headers={"content-type": "application/json"}), 422)
    assert _jobs_count(client) == before  # no job was stored


def test_non_finite_numbers_are_refused_by_the_schemas_too() -> None:
    from pydantic import ValidationError

    from schemas.graph import GraphRequest

    with pytest.raises(ValidationError, match="finite"):
        GraphRequest.model_validate(
            {
                "engine": "graph",
                "frames": 10,
                "constraints": [{"type": "body", "frame": 0, "position": [float("nan"), 0]}],
            }
        )


def test_deep_nesting_is_422_not_500(client: TestClient, walk_db: dict[str, Any]) -> None:
    deep = f'{{"engine": "clip", "database": "{walk_db["id"]}", "end": ' + "[" * 5000 + "]" * 5000 + "}"
    err = error_of(client.post("/v1/jobs", content=deep, headers={"content-type": "application/json"}), 422)
    assert "nested too deeply" in err["message"]
    deep_spec = '{"kind": "graph", "clips": ' + "[" * 5000 + "]" * 5000 + "}"
    error_of(
        client.post("/v1/databases", content=deep_spec, headers={"content-type": "application/json"}), 422
    )


def test_every_json_route_has_one_body_limit(
    client: TestClient, walk_db: dict[str, Any], override_settings: Callable[..., Settings]
) -> None:
    override_settings(max_json_bytes=1000)
    pad = " " * 2000
    for path in ("/v1/jobs", "/v1/databases", f"/v1/databases/{walk_db['id']}/corrections"):
        r = client.post(path, content="{}" + pad, headers={"content-type": "application/json"})
        assert "1000-byte limit" in error_of(r, 413, "too_large")["message"], path


@pytest.mark.parametrize(
    "content_type", ["text/plain", "application/x-www-form-urlencoded", "multipart/form-data; boundary=x", ""]
)
def test_cross_site_bodies_are_415(client: TestClient, walk_db: dict[str, Any], content_type: str) -> None:
    """A web page can send these content types anywhere without a preflight; JSON routes refuse them."""
    before = _jobs_count(client)
    body = json.dumps(_job(walk_db["id"]))
    headers = {"content-type": content_type} if content_type else {}
    error_of(client.post("/v1/jobs", content=body, headers=headers), 415, "unsupported_media_type")
    # a body sent with a bodyless write must be JSON too
    error_of(client.request("DELETE", f"/v1/databases/{walk_db['id']}", content=body, headers=headers), 415)
    assert _jobs_count(client) == before
    assert client.get(f"/v1/databases/{walk_db['id']}").status_code == 200


def test_host_and_origin_are_checked(client: TestClient, walk_db: dict[str, Any]) -> None:
    body = _job(walk_db["id"])
    # DNS rebinding: a foreign name pointed at this machine still sends its own Host
    error_of(client.post("/v1/jobs", json=body, headers={"host": "evil.example:8000"}), 400, "invalid_host")
    error_of(client.get("/v1/clips", headers={"host": "evil.example"}), 400, "invalid_host")
    for origin in ("http://evil.example", "null", "http://localhost:9999"):
        r = client.post("/v1/jobs", json=body, headers={"origin": origin})
        error_of(r, 403, "cross_origin")
    with (
        pytest.raises(WebSocketDenialResponse) as denied,
        client.websocket_connect("/v1/jobs/x/events", headers={"origin": "http://evil.example"}),
    ):
        pass
    assert denied.value.status_code == 403
    # the page itself is same-origin
    assert client.post("/v1/jobs", json=body, headers={"origin": "http://localhost"}).status_code == 202


def test_work_budget_is_checked_at_submission(
    client: TestClient, walk_db: dict[str, Any], override_settings: Callable[..., Settings]
) -> None:
    before = _jobs_count(client)
    override_settings(max_output_frames=5)
    err = error_of(client.post("/v1/jobs", json=_job(walk_db["id"])), 413, "over_budget")
    assert "10 output frames" in err["message"] and err["details"]["estimate"]["frames"] == 10
    override_settings(max_joint_frames=100)
    err = error_of(client.post("/v1/jobs", json=_job(walk_db["id"])), 413, "over_budget")
    assert "joint-frames" in err["message"] and err["details"]["limits"]["max_joint_frames"] == 100
    override_settings(max_job_seconds=5)
    err = error_of(client.post("/v1/jobs", json=_job(walk_db["id"], budget_s=60)), 413, "over_budget")
    assert "SEGUE_MAX_JOB_SECONDS" in err["message"]
    assert _jobs_count(client) == before


def test_work_estimate_counts_characters_frames_and_joints() -> None:
    from engines.base import DatabaseFacts
    from engines.registry import parse_job_request
    from workers.budget import WorkLimits, check_work, estimate_work

    crowd = parse_job_request(
        {"engine": "rhythm", "music": {"bpm": 120, "duration_s": 20}, "characters": 200, "database": "d"}
    )
    work = estimate_work(crowd, DatabaseFacts(120.0, 38, {}))
    assert (work.frames, work.characters, work.joint_frames) == (2400, 200, 2400 * 200 * 38)
    problems = check_work(work, WorkLimits())
    assert any("joint-frames" in p for p in problems) and any("MiB" in p for p in problems)
    long_graph = parse_job_request({"engine": "graph", "frames": 100_000, "database": "d"})
    assert any(
        "output frames" in p
        for p in check_work(estimate_work(long_graph, DatabaseFacts(30.0, 25, {})), WorkLimits())
    )


def test_reupload_with_other_units_is_a_conflict(client: TestClient, walk_clip: dict[str, Any]) -> None:
    other = "m" if walk_clip["units"] != "m" else "cm"
    r = client.post("/v1/clips", params={"units": other}, files={"file": (WALK.name, WALK.read_bytes())})
    err = error_of(r, 409, "units_conflict")
    assert walk_clip["units"] in err["message"]
    error_of(client.post("/v1/clips", params={"units": "furlong"}, files={"file": ("a.bvh", b"x")}), 422)


def test_nul_characters_are_refused(client: TestClient, walk_db: dict[str, Any]) -> None:
    spec = {"kind": "clips", "clips": [{"bvh": WALK.name, "name": "wa\u0000lk"}], "fps": 30}
    assert "NUL" in error_of(client.post("/v1/databases", json=spec), 422)["message"]
    r = client.post(
        "/v1/clips", params={"name": "a\x00b.bvh"}, files={"file": (WALK.name, WALK.read_bytes())}
    )
    assert error_of(r, 422, "invalid_name")["details"] == {"parameter": "name"}


def test_absurd_resampling_is_refused(client: TestClient, walk_db: dict[str, Any]) -> None:
    job = client.post("/v1/jobs", json=_job(walk_db["id"])).json()
    with client.websocket_connect(f"/v1/jobs/{job['id']}/events") as ws:
        while ws.receive_json()["type"] not in ("done", "failed", "cancelled"):
            pass
    error_of(client.get(f"/v1/jobs/{job['id']}/result", params={"fps": 1e-300}), 422)
    r = client.get(f"/v1/jobs/{job['id']}/result", params={"fps": 0.5, "format": "bvh"})
    assert r.status_code == 200
    from motion import parse_bvh

    parse_bvh(r.content)  # the service's own reader takes what the service writes


def test_a_500_keeps_the_connection(client: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
    """A bug answers the contract's 500 body and the connection stays usable (no re-raise)."""
    from workers.store import Store

    def broken(self: Store) -> list[Any]:
        raise RuntimeError("boom")

    monkeypatch.setattr(Store, "list_clips", broken)
    # raise_server_exceptions: the test fails if the server re-raised (which closes the connection)
    other = TestClient(client.app, raise_server_exceptions=True, base_url="http://localhost")
    error_of(other.get("/v1/clips"), 500, "internal")


def test_per_principal_job_limit_is_429(
    client: TestClient, walk_db: dict[str, Any], override_settings: Callable[..., Settings]
) -> None:
    client.app.state.job_quota.limit = 0  # type: ignore[attr-defined]
    try:
        r = client.post("/v1/jobs", json=_job(walk_db["id"]))
        error_of(r, 429, "too_many_jobs")
        assert r.headers["retry-after"]
    finally:
        client.app.state.job_quota.limit = 256  # type: ignore[attr-defined]


def test_database_size_is_checked_at_submission(
    client: TestClient, walk_clip: dict[str, Any], override_settings: Callable[..., Settings]
) -> None:
    override_settings(max_database_frames=50)  # the walk is 317 frames at 120 fps: 79 at 30 fps
    spec = {"kind": "clips", "clips": [{"clip": walk_clip["id"]}], "fps": 30}
    err = error_of(client.post("/v1/databases", json=spec), 413, "over_budget")
    assert err["details"] == {"frames": 79, "limit": 50}
