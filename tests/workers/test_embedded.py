"""The embedded backend end to end: builds, synthesis, cancellation, resume, worker loss."""

from __future__ import annotations

import asyncio
import os
import uuid
from pathlib import Path
from typing import Any

import pytest

from engines.registry import load_plugins
from motion.samples import sample_path
from schemas import DatabaseInfo, DatabaseStatus, EventType, JobEvent, JobInfo, JobStatus
from schemas.databases import database_id, parse_database_spec
from schemas.jobs import JobKind
from workers.embedded import EmbeddedBackend
from workers.store import Store, now

PLUGIN = "tests.workers.scripted_engine"
ROOT = str(Path(__file__).resolve().parents[2])


@pytest.fixture(autouse=True)
def _plugin_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SEGUE_ENGINE_PLUGINS", PLUGIN)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [ROOT, os.environ.get("PYTHONPATH")])))
    load_plugins(PLUGIN)


async def _collect(backend: EmbeddedBackend, job_id: str, after: int = 0) -> list[JobEvent]:
    return [e async for e in backend.events(job_id, after)]


async def _submit(
    backend: EmbeddedBackend, store: Store, kind: str, payload: dict[str, Any], **info: Any
) -> str:
    job_id = uuid.uuid4().hex
    job = JobInfo(id=job_id, kind=JobKind(kind), status=JobStatus.queued, created_at=now(), **info)
    store.put_job(job, {"kind": kind, "payload": payload})
    await backend.submit(job, kind, payload)
    return job_id


async def _database(backend: EmbeddedBackend, store: Store) -> str:
    clip = store.put_clip("walk.bvh.gz", sample_path("walk").read_bytes())
    spec = parse_database_spec({"kind": "clips", "clips": [{"clip": clip.id, "name": "walk"}], "fps": 30})
    db_id = database_id(spec, [clip.id])
    store.put_database_info(
        DatabaseInfo(id=db_id, kind="clips", status=DatabaseStatus.queued, clips=["walk"], created_at=now()),
        spec.model_dump(mode="json"),
    )
    job = await _submit(backend, store, "build", {"database": db_id}, database=db_id)
    events = await _collect(backend, job)
    assert events[-1].type == EventType.done, events[-1]
    assert store.database_info(db_id).status == DatabaseStatus.ready
    return db_id


def test_build_synth_cancel_and_resume(tmp_path: Path) -> None:
    async def scenario() -> None:
        store = Store(tmp_path)
        backend = EmbeddedBackend(store, workers=2)
        await backend.start()
        try:
            db = await _database(backend, store)
            # a clip job: queued, started, solution, done, ids 1..4
            job = await _submit(
                backend,
                store,
                "synth",
                {"request": {"engine": "clip", "clip": "walk", "database": db, "end": 40}},
            )
            events = await _collect(backend, job)
            assert [e.type for e in events] == ["queued", "started", "solution", "done"]
            assert [e.id for e in events] == [1, 2, 3, 4]
            assert store.job_info(job).status == JobStatus.done and store.job_info(job).result == "r1"
            assert store.result_motion(job, "r1").num_frames == 40
            # resume: only what came after event 2
            assert [e.id for e in await _collect(backend, job, after=2)] == [3, 4]
            # cancel an anytime search mid-way: cancelled, with the best result so far
            slow = await _submit(
                backend,
                store,
                "synth",
                {"request": {"engine": "scripted", "database": db, "steps": 50, "step_s": 0.05}},
            )
            seen: list[JobEvent] = []
            async for event in backend.events(slow):
                seen.append(event)
                if event.type == EventType.solution and event.data["result"] == "r3":
                    await backend.cancel(slow)
            assert seen[-1].type == EventType.cancelled
            best = seen[-1].data["result"]
            assert best is not None and int(best[1:]) >= 3
            assert store.result_report(slow, best).engine == "scripted"
            assert store.job_info(slow).status == JobStatus.cancelled
            # an engine error fails the job with a message, and the backend keeps working
            bad = await _submit(
                backend, store, "synth", {"request": {"engine": "clip", "clip": "nope", "database": db}}
            )
            last = (await _collect(backend, bad))[-1]
            assert last.type == EventType.failed and "no clip named 'nope'" in last.data["error"]["message"]
        finally:
            await backend.close()

    asyncio.run(asyncio.wait_for(scenario(), 120))


def test_events_survive_a_restart(tmp_path: Path) -> None:
    async def first() -> tuple[str, str]:
        store = Store(tmp_path)
        backend = EmbeddedBackend(store, workers=1)
        await backend.start()
        try:
            db = await _database(backend, store)
            job = await _submit(
                backend, store, "synth", {"request": {"engine": "clip", "clip": "walk", "database": db}}
            )
            await _collect(backend, job)
            return db, job
        finally:
            await backend.close()

    async def second(job: str) -> list[JobEvent]:
        backend = EmbeddedBackend(Store(tmp_path), workers=1)
        await backend.start()
        try:
            return await _collect(backend, job)
        finally:
            await backend.close()

    _, job = asyncio.run(asyncio.wait_for(first(), 120))
    replay = asyncio.run(asyncio.wait_for(second(job), 120))
    assert [e.type for e in replay] == ["queued", "started", "solution", "done"]


def test_jobs_left_running_by_a_dead_server_fail_at_start(tmp_path: Path) -> None:
    store = Store(tmp_path)
    stale = JobInfo(id="stale1", kind=JobKind.synth, status=JobStatus.running, created_at=now())
    store.put_job(stale, {"kind": "synth", "payload": {"request": {}}})

    async def scenario() -> list[JobEvent]:
        backend = EmbeddedBackend(store, workers=1)
        await backend.start()
        try:
            return await _collect(backend, "stale1")
        finally:
            await backend.close()

    events = asyncio.run(asyncio.wait_for(scenario(), 60))
    assert events[-1].type == EventType.failed
    assert events[-1].data["error"]["code"] == "server_restarted"
    assert store.job_info("stale1").status == JobStatus.failed
