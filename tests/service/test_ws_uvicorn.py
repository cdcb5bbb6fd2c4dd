"""The API under a real uvicorn on 127.0.0.1: upload -> build -> submit -> stream, drop and resume
the WebSocket, download the GLB. (The submit -> first worker event latency is a figure of
``bench/service.py``, ``first_event_p50_ms``, not a test.)"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import connect

from service.client import SegueClient, SegueError
from tests.live_server import live_server

from .conftest import PLUGINS, WALK, WALK_CLIP


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """Base URL of ``uvicorn --factory service.app:create_app`` in a subprocess (2 embedded workers)."""
    with live_server(tmp_path_factory.mktemp("uvicorn-data"), plugins=PLUGINS) as url:
        yield url


@pytest.fixture(scope="module")
def segue(server: str) -> Iterator[SegueClient]:
    with SegueClient(server) as client:
        yield client


@pytest.fixture(scope="module")
def database(segue: SegueClient) -> str:
    clip = segue.upload_clip(WALK)
    db = segue.build_database({"kind": "clips", "clips": [{"bvh": clip.name}], "fps": 30})
    assert db.status == "ready" and db.clips == [WALK_CLIP]
    return db.id


def _ws_url(server: str, job_id: str, after: int = 0) -> str:
    return f"ws{server.removeprefix('http')}/v1/jobs/{job_id}/events?after={after}"


def test_stream_drop_resume_and_download(
    server: str, segue: SegueClient, database: str, tmp_path: Path
) -> None:
    job = segue.submit({"engine": "scripted", "database": database, "steps": 8, "step_s": 0.03})
    first: list[dict[str, Any]] = []
    with connect(_ws_url(server, job.id)) as ws:
        while len(first) < 4:
            first.append(json.loads(ws.recv(timeout=120)))
    # the socket is gone mid-stream; resume after the last event seen
    rest: list[dict[str, Any]] = []
    with connect(_ws_url(server, job.id, after=first[-1]["id"])) as ws:
        for message in ws:  # ends when the server closes with 1000 after the terminal event
            rest.append(json.loads(message))
        assert ws.close_code == 1000
    events = first + rest
    assert [e["id"] for e in events] == list(range(1, len(events) + 1))
    assert rest[0]["id"] == first[-1]["id"] + 1 and rest[-1]["type"] == "done"
    assert sum(e["type"] == "solution" for e in events) == 8
    glb = segue.result(job.id, "glb", tmp_path / "out.glb")
    assert glb[:4] == b"glTF" and (tmp_path / "out.glb").stat().st_size == len(glb)
    # the client's iterator sees the same events
    assert [e.id for e in segue.events(job.id)] == [e["id"] for e in events]
    assert segue.report(job.id).provenance[0].clip == WALK_CLIP


def test_client_errors_and_unknown_job_close(server: str, segue: SegueClient) -> None:
    with pytest.raises(SegueError) as exc:
        list(segue.events("0" * 32))
    assert exc.value.status == 404
    with connect(_ws_url(server, "0" * 32)) as ws:
        with pytest.raises(Exception):  # noqa: B017, PT011 - the close frame ends recv
            ws.recv(timeout=120)
        assert ws.close_code == 4404
    with pytest.raises(SegueError) as exc:
        segue.submit({"engine": "clip", "clip": "x"})
    assert exc.value.status == 422 and exc.value.code == "invalid_request"


def test_client_cancels_and_deletes_with_plain_requests(segue: SegueClient, database: str) -> None:
    """``SegueClient`` sends cancel and delete as ``curl -X`` does: no body, no content type."""
    job = segue.submit({"engine": "scripted", "database": database, "steps": 500, "step_s": 0.05})
    with pytest.raises(SegueError) as exc:
        segue.delete_job(job.id)
    assert exc.value.status == 409 and exc.value.code == "job_not_finished"
    segue.cancel(job.id)
    assert list(segue.events(job.id))[-1].type == "cancelled"
    segue.delete_job(job.id)
    with pytest.raises(SegueError) as exc:
        segue.job(job.id)
    assert exc.value.status == 404
