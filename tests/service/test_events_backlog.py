"""``GET /v1/jobs/{id}/events`` without ``wait`` answers with every event a finished job has,
however long loading them takes (it once answered ``[]`` when the store's archive took longer
than 50 ms to read, and all the events when asked again)."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest

from schemas import EventType, JobEvent, JobInfo, JobStatus
from schemas.jobs import JobKind
from service.routes.events import collect_events
from workers.embedded import EmbeddedBackend
from workers.store import Store, now

TYPES = ["queued", "started", *["solution"] * 7, "done"]


def finished_job(store: Store) -> JobInfo:
    """A job a previous server process ran: its record and its 10 archived events on disk."""
    info = JobInfo(
        id="a" * 32,
        kind=JobKind.synth,
        engine="scripted",
        status=JobStatus.done,
        created_at=now(),
        last_event=len(TYPES),
        result="r7",
    )
    store.put_job(info, {"kind": "synth", "payload": {}})
    lines = [
        JobEvent(id=i, job=info.id, type=EventType(t), time=time.time(), data={}).model_dump_json()
        for i, t in enumerate(TYPES, start=1)
    ]
    store.put_events(info.id, lines)
    return info


@pytest.fixture
def slow_backend(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[EmbeddedBackend, JobInfo]:
    """A fresh backend (nothing in its hub) whose archive reads take 0.3 s, as on a loaded machine."""
    store = Store(tmp_path)
    job = finished_job(store)
    backend = EmbeddedBackend(store)
    read = backend._archived

    def slow(job_id: str) -> list[JobEvent]:
        time.sleep(0.3)
        return read(job_id)

    monkeypatch.setattr(backend, "_archived", slow)
    return backend, job


def test_a_finished_job_answers_every_event_at_once(slow_backend: tuple[EmbeddedBackend, JobInfo]) -> None:
    backend, job = slow_backend

    async def scenario() -> tuple[list[JobEvent], list[JobEvent], list[JobEvent]]:
        first, second = await asyncio.gather(
            collect_events(backend, job.id, 0, 0), collect_events(backend, job.id, 0, 0)
        )
        return first, second, await collect_events(backend, job.id, 4, 0)

    first, second, after = asyncio.run(scenario())
    assert [e.type.value for e in first] == TYPES
    assert second == first
    assert [e.id for e in after] == list(range(5, len(TYPES) + 1))


def test_a_long_poll_of_a_finished_job_answers_at_once(slow_backend: tuple[EmbeddedBackend, JobInfo]) -> None:
    backend, job = slow_backend
    got = asyncio.run(collect_events(backend, job.id, 0, 30))
    assert [e.type.value for e in got] == TYPES
    assert asyncio.run(collect_events(backend, job.id, len(TYPES), 30)) == []
