"""Issue 40, items 8-10: bounded upload memory and upload slots, a stalled store answered 503 with
readiness telling the truth, and the validation gaps (result ids, clip names, database rates, a
client that disconnects)."""

from __future__ import annotations

import logging
import threading
import tracemalloc
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from starlette.types import Message

from workers.objects import Objects

from .conftest import WALK, WALK_CLIP, wait_events
from .test_api import error_of

GUARD_S = 60.0
"""Hang guard of a stalled call (never a speed bar)."""


def _finished_job(client: TestClient, db: str) -> str:
    job = client.post("/v1/jobs", json={"engine": "clip", "database": db, "clip": WALK_CLIP, "end": 10})
    assert job.status_code == 202, job.text
    assert wait_events(client, job.json()["id"])[-1]["type"] == "done"
    return str(job.json()["id"])


# -- item 10: validation gaps ------------------------------------------------------------------
@pytest.mark.parametrize("bad", ["\u00e9", "\n", "\x7f", "a/b", "r1 "])
def test_bad_result_ids_are_422_naming_the_parameter(
    client: TestClient, walk_db: dict[str, Any], bad: str
) -> None:
    """``?result=%C3%A9`` (also ``%0A``, ``%7F``) was a 500 ``invalid object key``."""
    job = _finished_job(client, walk_db["id"])
    for route, params in (("result", {"format": "glb"}), ("result", {}), ("report", {})):
        r = client.get(f"/v1/jobs/{job}/{route}", params={"result": bad, **params})
        body = error_of(r, 422, "invalid_request")
        assert "result" in str(body), body


@pytest.mark.parametrize("kind", ["clips", "graph", "rhythm"])
@pytest.mark.parametrize("fps", [1e-300, 0.5, 0, 1001])
def test_database_rates_are_bounded(
    client: TestClient, walk_clip: dict[str, Any], kind: str, fps: float
) -> None:
    """A database at ``fps: 1e-300`` was accepted (its results had ``Frame Time: 1e300``)."""
    spec = {"kind": kind, "clips": [{"bvh": walk_clip["name"]}], "fps": fps}
    body = error_of(client.post("/v1/databases", json=spec), 422, "invalid_request")
    assert "fps" in str(body), body


@pytest.mark.parametrize("name", ["..", ".", "/", "a/..", "  ", "walk\x01.bvh", "walk\n.bvh", "\x7f"])
def test_unusable_clip_names_are_refused(client: TestClient, name: str) -> None:
    """A clip named ``..`` was stored but could not be reached again; control characters were
    silently dropped. Both are 422 ``invalid_name`` naming where the name came from."""
    data = WALK.read_bytes()
    raw = client.post("/v1/clips", params={"name": name}, content=data)
    assert error_of(raw, 422, "invalid_name")["details"] == {"parameter": "name"}
    if name in ("..", ".", "a/.."):  # (the HTTP client escapes control characters in file names)
        multipart = client.post("/v1/clips", files={"file": (name, data)})
        assert error_of(multipart, 422, "invalid_name")["details"] == {"parameter": "file name"}
    files = client.post("/v1/files", params={"name": name}, content=b"MThd")
    error_of(files, 422, "invalid_name")


def test_directories_are_still_stripped_from_names(client: TestClient) -> None:
    """A browser's or a path's directories are not the name: ``clips/walk.bvh.gz`` is stored as
    ``walk.bvh.gz`` (what it was before)."""
    r = client.post("/v1/clips", params={"name": f"some/dir/{WALK.name}"}, content=WALK.read_bytes())
    assert r.status_code in (200, 201), r.text
    assert r.json()["name"] == WALK.name


def _asgi(
    client: TestClient,
    app: FastAPI,
    path: str,
    query: str,
    chunks: Iterator[bytes],
    length: int,
    then_disconnect: bool,
) -> list[Message]:
    """Drive one raw-body POST through the app as a server would, feeding ``chunks`` (none held
    by the test beyond the current one), then a disconnect when ``then_disconnect``; the messages
    the app sent."""
    sent: list[Message] = []
    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": path,
        "raw_path": path.encode(),
        "root_path": "",
        "query_string": query.encode(),
        "headers": [
            (b"host", b"localhost"),
            (b"content-type", b"application/octet-stream"),
            (b"content-length", str(length).encode()),
        ],
        "client": ("127.0.0.1", 5000),
        "server": ("localhost", 80),
    }
    done = False

    async def receive() -> Message:
        nonlocal done
        if not done:
            chunk = next(chunks, None)
            if chunk is not None:
                return {"type": "http.request", "body": chunk, "more_body": True}
            done = True
            if not then_disconnect:
                return {"type": "http.request", "body": b"", "more_body": False}
        return {"type": "http.disconnect"}

    async def send(message: Message) -> None:
        sent.append(message)

    assert client.portal is not None
    client.portal.call(app, scope, receive, send)
    return sent


def test_a_client_disconnect_is_one_line_and_no_500(
    client: TestClient, app: FastAPI, caplog: pytest.LogCaptureFixture
) -> None:
    """A client that left mid-upload was logged as a 56-line traceback and counted as a 500."""

    def before() -> float:
        return _count_500(client.get("/metrics").text, "/v1/files")

    count = before()
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="segue.service"):
        sent = _asgi(client, app, "/v1/files", "name=left.mid", iter([b"MThd" * 1000]), 10**6, True)
    assert [m["status"] for m in sent if m["type"] == "http.response.start"] in ([], [499])
    records = [r for r in caplog.records if r.name.startswith("segue")]
    assert not any(r.exc_info for r in records), [r.getMessage() for r in records]
    assert sum("disconnected" in r.getMessage() for r in records) == 1
    assert before() == count


def _count_500(metrics: str, route: str) -> float:
    total = 0.0
    for line in metrics.splitlines():
        if (
            line.startswith("segue_http_requests_total")
            and f'route="{route}"' in line
            and 'status="500"' in line
        ):
            total += float(line.rsplit(" ", 1)[1])
    return total


# -- item 8: bounded upload memory ---------------------------------------------------------------
def test_an_upload_is_never_held_whole_in_memory(client: TestClient, app: FastAPI) -> None:
    """A 24 MiB upload used to be joined into one bytes object (and copied again on its way to
    the store): 8 parallel 60 MiB uploads took the API from 496 to 1,175 MiB. It is spooled and
    stored in 1 MiB chunks: the Python heap grows by a few MiB whatever the upload's size."""
    piece = bytes(range(256)) * 256  # 64 KiB, the size a server hands over
    pieces = 24 * 16

    def chunks() -> Iterator[bytes]:
        yield b"MThd" + piece[4:]
        for i in range(1, pieces):
            yield piece if i % 2 else piece[::-1]

    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        sent = _asgi(client, app, "/v1/files", "name=big.bin", chunks(), pieces * len(piece), False)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    status = next(m["status"] for m in sent if m["type"] == "http.response.start")
    assert status in (200, 201), sent
    assert peak - base < 8 << 20, f"the upload held {(peak - base) / 2**20:.1f} MiB at once"
    listed = {f["name"]: f for f in client.get("/v1/files").json()}
    assert listed["big.bin"]["size_bytes"] == pieces * len(piece)
    assert listed["big.bin"]["media_type"] == "audio/midi"


def test_a_large_clip_goes_to_a_worker_from_its_spooled_file(
    client: TestClient, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A clip over the in-memory bound is streamed to the staging area and parsed by a worker;
    the answer is the same clip as an in-memory parse gives."""
    monkeypatch.setattr("service.uploads.INLINE_UPLOAD_BYTES", 1024)
    monkeypatch.setattr("service.routes.clips.INLINE_UPLOAD_BYTES", 1024)
    data = WALK.read_bytes()
    r = client.post("/v1/clips", params={"name": "streamed.bvh.gz"}, content=data + b"")
    assert r.status_code in (200, 201), r.text
    info = r.json()
    assert info["frames"] == 317 and info["size_bytes"] == len(data)
    assert client.get(f"/v1/clips/{info['id']}/bvh").content == data
    assert client.app.state.store.objects.children("staged") == []  # type: ignore[attr-defined]


def test_uploads_beyond_the_limit_are_503_with_retry_after(client: TestClient, app: FastAPI) -> None:
    from service.uploads import UploadSlots

    saved = getattr(app.state, "upload_slots", None)
    slots = UploadSlots(1)
    slots.take()  # one upload in flight: the limit
    app.state.upload_slots = slots
    try:
        r = client.post("/v1/files", params={"name": "busy.mid"}, content=b"MThd")
        body = error_of(r, 503, "too_many_uploads")
        assert body["details"] == {"max_uploads": 1} and int(r.headers["Retry-After"]) > 0
        slots.give()
        r = client.post("/v1/files", params={"name": "busy.mid"}, content=b"MThd")
        assert r.status_code in (200, 201), r.text
        assert slots.in_flight == 0  # given back after the answer
    finally:
        app.state.upload_slots = saved


# -- item 9: a stalled store ---------------------------------------------------------------------
class Stalling:
    """An object store that stops answering while ``stalled`` is set (each call waits until it is
    cleared, at most :data:`GUARD_S`), as a SIGSTOPped server or a hung mount does."""

    def __init__(self, inner: Objects) -> None:
        self.inner = inner
        self.url = inner.url
        self.stalled = threading.Event()
        self.resumed = threading.Event()
        self.resumed.set()

    def __getattr__(self, name: str) -> Any:
        value = getattr(self.inner, name)
        if not callable(value) or name == "local_path":
            return value

        def call(*args: Any, **kwargs: Any) -> Any:
            if self.stalled.is_set():
                self.resumed.wait(GUARD_S)
            return value(*args, **kwargs)

        return call

    def stall(self) -> None:
        self.resumed.clear()
        self.stalled.set()

    def resume(self) -> None:
        self.stalled.clear()
        self.resumed.set()


@pytest.fixture
def stalling_store(app: FastAPI, client: TestClient) -> Iterator[Callable[[], Stalling]]:
    from workers.timed_objects import TimedObjects

    timed = app.state.store.objects
    assert isinstance(timed, TimedObjects)
    inner, timeout = timed.inner, timed.timeout_s
    fake = Stalling(inner)
    timed.inner, timed.timeout_s = fake, 0.5
    try:
        yield lambda: fake
    finally:
        fake.resume()
        timed.inner, timed.timeout_s = inner, timeout


def test_a_stalled_store_is_503_and_not_ready(
    client: TestClient, walk_db: dict[str, Any], stalling_store: Callable[[], Stalling]
) -> None:
    """A store stall hung ``GET /v1/jobs/{id}`` (over 8 s; 96 s in all) while ``/healthz`` said ok.
    A stalled store is answered 503 ``store_unavailable`` with ``Retry-After``; ``/readyz`` names
    the store; ``/healthz`` (liveness) still answers."""
    job = _finished_job(client, walk_db["id"])
    assert client.get("/readyz").json() == {
        "ready": True,
        "checks": {"store": "ok", "backend": "ok", "workers": "ok"},
    }
    fake = stalling_store()
    fake.stall()
    try:
        r = client.get(f"/v1/jobs/{job}")
        error_of(r, 503, "store_unavailable")
        assert int(r.headers["Retry-After"]) > 0
        error_of(client.get("/v1/jobs"), 503, "store_unavailable")
        ready = client.get("/readyz")
        assert ready.status_code == 503
        assert ready.json()["ready"] is False and "store" in ready.json()["not_ready"]
        assert "store" not in ready.json()["checks"]
        assert client.get("/healthz").status_code == 200
    finally:
        fake.resume()
    assert client.get(f"/v1/jobs/{job}").status_code == 200
    assert client.get("/readyz").status_code == 200


@pytest.mark.parametrize(
    ("health", "part"),
    [
        ({"backend": "redis", "redis": "unreachable", "error": "Redis is unreachable: refused"}, "redis"),
        ({"backend": "redis", "redis": "ok", "workers": 0}, "workers"),
        ({"backend": "embedded", "workers": 2, "workers_ready": 0}, "workers"),
    ],
)
def test_readiness_names_the_part_that_is_not_ready(
    client: TestClient, app: FastAPI, monkeypatch: pytest.MonkeyPatch, health: dict[str, Any], part: str
) -> None:
    """Redis away or no live worker: ``/readyz`` is 503 naming it, while the store is ``ok``."""

    async def facts() -> dict[str, Any]:
        return health

    monkeypatch.setattr(app.state.backend, "health", facts)
    r = client.get("/readyz")
    assert r.status_code == 503
    assert list(r.json()["not_ready"]) == [part] and r.json()["checks"]["store"] == "ok"
