"""No engine-sized work in the API process: large uploads are parsed, large exports and every
retargeting made by a worker (a small job), answers streamed from the store and the same bytes as
when the API made them itself."""

from __future__ import annotations

import gzip
import io
import time
from collections.abc import Callable
from typing import Any

import pytest
from fastapi.testclient import TestClient

from motion import BvhError, parse_bvh, write_bvh
from schemas import JobInfo
from tests.motion.retarget.characters import character
from workers.settings import Settings
from workers.store import Store

from .conftest import WALK_CLIP, wait_events
from .test_api import error_of, submit


def _bvh(scale: float) -> bytes:
    buf = io.StringIO()
    write_bvh(character("mixamo", scale=scale), buf)
    return buf.getvalue().encode()


def _no_parse_here(*args: Any, **kwargs: Any) -> Any:
    raise AssertionError("the API process parsed a whole BVH table")


@pytest.fixture
def worker_sized(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every upload and export is 'large': the API process must hand them to a worker (and any
    full parse or export in this process fails the test)."""
    monkeypatch.setattr("service.uploads.INLINE_VALUES", 0)
    monkeypatch.setattr("workers.result_export.INLINE_JOINT_FRAMES", 0)
    monkeypatch.setattr("workers.store.parse_motion", _no_parse_here)
    monkeypatch.setattr("service.exports.make_export", _no_parse_here)


@pytest.fixture(scope="module")
def walk_job(client: TestClient, walk_db: dict[str, Any]) -> str:
    job = submit(
        client, {"engine": "clip", "database": walk_db["id"], "clip": WALK_CLIP, "start": 0, "end": 60}
    )
    assert wait_events(client, job["id"])[-1]["type"] == "done"
    return str(job["id"])


def _store(client: TestClient) -> Store:
    store = client.app.state.store  # type: ignore[attr-defined]
    assert isinstance(store, Store)
    return store


def _no_task_jobs_left(client: TestClient) -> None:
    """Small jobs never show in listings and are removed once answered (a hang guard of 60 s)."""
    assert all(j["kind"] != "task" for j in client.get("/v1/jobs").json())
    deadline = time.monotonic() + 60
    while any(j.kind == "task" for j in _store(client).list_jobs()):
        assert time.monotonic() < deadline, "a finished small job was not removed"
        time.sleep(0.1)


@pytest.mark.usefixtures("worker_sized")
def test_a_large_clip_is_parsed_by_a_worker(client: TestClient) -> None:
    data = gzip.compress(_bvh(1.31))
    r = client.post("/v1/clips", files={"file": ("big-char.bvh.gz", data)})
    assert r.status_code == 201, r.text
    info = r.json()
    motion = parse_bvh(data)
    assert info["frames"] == motion.num_frames and info["joints"] == list(motion.skeleton.names)
    assert info["units"] == motion.units and info["name"] == "big-char.bvh.gz"
    again = client.post("/v1/clips", files={"file": ("big-char.bvh.gz", data)})
    assert again.status_code == 200 and again.json()["id"] == info["id"]
    _no_task_jobs_left(client)


@pytest.mark.usefixtures("worker_sized")
def test_a_bad_table_is_refused_with_the_parsers_own_message(client: TestClient) -> None:
    lines = _bvh(1.37).decode().rstrip("\n").split("\n")
    lines[-1] = lines[-1].rsplit(" ", 1)[0] + " 1.0x"  # the last number of the last frame
    data = ("\n".join(lines) + "\n").encode()
    with pytest.raises(BvhError) as expected:
        parse_bvh(data, source="bad.bvh", name="bad.bvh")
    body = error_of(client.post("/v1/clips", params={"name": "bad.bvh"}, content=data), 400, "invalid_bvh")
    assert body["message"] == str(expected.value)
    assert not any(c["name"] == "bad.bvh" for c in client.get("/v1/clips").json())
    _no_task_jobs_left(client)


@pytest.mark.usefixtures("worker_sized")
def test_a_header_fault_is_refused_without_a_parse(client: TestClient, override_settings: Any) -> None:
    override_settings(max_bvh_bytes=2000)  # the inflate cap, checked while inflating in chunks
    data = gzip.compress(_bvh(1.41))
    body = error_of(client.post("/v1/clips", files={"file": ("bomb.bvh.gz", data)}), 400, "invalid_bvh")
    assert "decompressed file is larger than the 2000-byte limit" in body["message"]
    override_settings(max_bvh_bytes=None)
    lines = _bvh(1.43).decode().replace("Frames: ", "Frames: x", 1)
    body = error_of(client.post("/v1/clips", params={"name": "x.bvh"}, content=lines.encode()), 400)
    assert "is not an integer" in body["message"]


def test_a_worker_export_is_the_bytes_the_api_made(
    client: TestClient, walk_job: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    params = {"format": "json", "max_fps": 24, "events": "contacts"}
    inline = client.get(f"/v1/jobs/{walk_job}/result", params=params)
    assert inline.status_code == 200, inline.text
    _store(client).objects.delete_prefix(f"jobs/{walk_job}/exports")  # forget the stored export
    monkeypatch.setattr("workers.result_export.INLINE_JOINT_FRAMES", 0)
    monkeypatch.setattr("service.exports.make_export", _no_parse_here)
    made = client.get(f"/v1/jobs/{walk_job}/result", params=params)
    assert made.status_code == 200, made.text
    assert made.content == inline.content
    assert made.headers["content-type"] == inline.headers["content-type"]
    assert made.headers["content-disposition"] == inline.headers["content-disposition"]
    cached = client.get(f"/v1/jobs/{walk_job}/result", params=params)  # streamed from the store
    assert cached.content == inline.content
    _no_task_jobs_left(client)


@pytest.mark.usefixtures("worker_sized")
def test_parallel_character_downloads_share_one_small_job(client: TestClient, walk_job: str) -> None:
    from concurrent.futures import ThreadPoolExecutor

    clip = client.post("/v1/clips", files={"file": ("char-47.bvh", _bvh(1.47))}).json()
    query = {"format": "bvh", "character": clip["id"]}
    with ThreadPoolExecutor(4) as pool:
        answers = list(pool.map(lambda _: client.get(f"/v1/jobs/{walk_job}/result", params=query), range(4)))
    assert all(a.status_code == 200 for a in answers), [a.text for a in answers]
    assert len({a.content for a in answers}) == 1
    assert parse_bvh(answers[0].content).skeleton.names == character("mixamo").skeleton.names
    _no_task_jobs_left(client)


def test_a_resampling_past_the_joint_frame_limit_is_413(
    client: TestClient, walk_job: str, override_settings: Any
) -> None:
    override_settings(max_joint_frames=5000)
    r = client.get(f"/v1/jobs/{walk_job}/result", params={"format": "json", "fps": 1000})
    assert "joint-frames" in error_of(r, 413, "too_large")["message"]


@pytest.mark.usefixtures("worker_sized")
def test_a_worker_parse_is_the_uploaders_small_job(
    client: TestClient, override_settings: Callable[..., Settings], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Fair scheduling serves a small job in its principal's line: it is submitted with its owner."""
    override_settings(api_tokens=("gina:tg",))
    backend = client.app.state.backend  # type: ignore[attr-defined]
    submitted: list[tuple[str, str | None]] = []
    submit_job = backend.submit

    async def spy(info: JobInfo, kind: str, payload: dict[str, Any]) -> JobInfo:
        submitted.append((info.kind.value, info.owner))
        return await submit_job(info, kind, payload)

    monkeypatch.setattr(backend, "submit", spy)
    data = _bvh(4.0 + time.time_ns() % 971 / 1e4)
    r = client.post("/v1/clips", files={"file": ("gina.bvh", data)}, headers={"Authorization": "Bearer tg"})
    assert r.status_code == 201, r.text
    assert submitted == [("task", "gina")]
