"""A database record always ends ``ready`` or ``failed`` with a reason: a build cancelled while
queued, or killed by its time limit, leaves it ``failed`` (before, it stayed ``queued`` or
``building`` for good and ``build_database`` waited on it), on both backends."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path

import pytest

from engines.registry import load_plugins, parse_database_spec
from motion.samples import sample_path
from schemas import DatabaseInfo, DatabaseStatus, EventType, JobEvent, JobStatus
from schemas.databases import database_id
from workers.embedded import EmbeddedBackend
from workers.redis_backend import RedisBackend
from workers.store import Store, now

from .conftest import PLUGINS, REPO, add_database, new_job, run, synth, worker_thread


@pytest.fixture(autouse=True)
def _plugin_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SEGUE_ENGINE_PLUGINS", PLUGINS)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    load_plugins(PLUGINS)


def graph_record(store: Store, fps: float = 30.0) -> str:
    """A queued ``graph`` database of the walk sample (a build that takes seconds, not milliseconds)."""
    clip = store.put_clip("walk.bvh.gz", sample_path("walk").read_bytes())
    spec = parse_database_spec({"kind": "graph", "clips": [{"clip": clip.id, "name": "walk"}], "fps": fps})
    db_id = database_id(spec, [clip.id])
    queued = DatabaseStatus.queued
    info = DatabaseInfo(id=db_id, kind="graph", status=queued, clips=["walk"], created_at=now())
    store.put_database_info(info, spec.model_dump(mode="json"))
    return db_id


def build_job(store: Store, db_id: str) -> str:
    job = new_job(store, "build", {"database": db_id})
    store.put_database_info(store.database_info(db_id).model_copy(update={"build_job": job.id}))
    return job.id


async def collect(backend: EmbeddedBackend | RedisBackend, job_id: str) -> list[JobEvent]:
    return [e async for e in backend.events(job_id)]


def test_embedded_build_cancelled_while_queued_or_killed_ends_failed(tmp_path: Path) -> None:
    store = Store(tmp_path / "data")
    busy_db = add_database(store)
    queued_db, killed_db = graph_record(store), graph_record(store, fps=24.0)

    async def scenario() -> tuple[list[JobEvent], list[JobEvent]]:
        backend = EmbeddedBackend(store, 1, build_timeout_s=0.05)
        await backend.start()
        try:
            # the only engine process is busy: the build waits in the queue and is cancelled there
            busy, payload = synth(store, busy_db, steps=500, step_s=0.05)
            await backend.submit(busy, "synth", payload)
            job = build_job(store, queued_db)
            await backend.submit(store.job_info(job), "build", {"database": queued_db})
            await backend.cancel(job)
            cancelled = await collect(backend, job)
            await backend.cancel(busy.id)
            await collect(backend, busy.id)
            # a build killed by its time limit (0.05 s: the graph build cannot finish in time)
            job = build_job(store, killed_db)
            await backend.submit(store.job_info(job), "build", {"database": killed_db})
            return cancelled, await collect(backend, job)
        finally:
            await backend.close()

    cancelled, killed = asyncio.run(asyncio.wait_for(scenario(), 240))
    assert [e.type for e in cancelled] == [EventType.queued, EventType.cancelled]
    db = store.database_info(queued_db)
    assert db.status == DatabaseStatus.failed and db.error == "the build was cancelled"
    assert killed[-1].type == EventType.failed and killed[-1].data["error"]["code"] == "time_limit"
    db = store.database_info(killed_db)
    assert db.status == DatabaseStatus.failed and "time limit" in str(db.error)
    assert store.job_info(killed[-1].job).status == JobStatus.failed


def test_redis_build_cancelled_while_queued_or_killed_ends_failed(redis_url: str, store: Store) -> None:
    queued_db, killed_db = graph_record(store), graph_record(store, fps=24.0)

    async def cancel_queued() -> list[JobEvent]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            job = build_job(store, queued_db)
            await backend.submit(store.job_info(job), "build", {"database": queued_db})
            await backend.cancel(job)  # no worker yet: the API ends it (and settles the record)
            return await collect(backend, job)
        finally:
            await backend.close()

    async def killed_build() -> list[JobEvent]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            job = build_job(store, killed_db)
            await backend.submit(store.job_info(job), "build", {"database": killed_db})
            return await collect(backend, job)
        finally:
            await backend.close()

    cancelled = run(cancel_queued())
    assert [e.type for e in cancelled] == [EventType.queued, EventType.cancelled]
    db = store.database_info(queued_db)
    assert db.status == DatabaseStatus.failed and db.error == "the build was cancelled"
    with worker_thread(redis_url, store, "t1", build_timeout_s=0.05):
        killed = run(asyncio.wait_for(killed_build(), 240))
    assert killed[-1].type == EventType.failed and killed[-1].data["error"]["code"] == "time_limit"
    db = store.database_info(killed_db)
    assert db.status == DatabaseStatus.failed and "time limit" in str(db.error)


def test_a_newer_build_keeps_its_record(tmp_path: Path) -> None:
    """Only the record's own build job settles it: an older build's end leaves a newer one alone."""
    from schemas.jobs import JobKind
    from workers.records import settle_database

    store = Store(tmp_path / "data")
    db_id = graph_record(store)
    old = new_job(store, "build", {"database": db_id})
    build_job(store, db_id)  # re-posted: a newer build job owns the record
    event = JobEvent(id=2, job=old.id, type=EventType.cancelled, time=0.0)
    settle_database(store, old.model_copy(update={"kind": JobKind.build, "database": db_id}), event)
    assert store.database_info(db_id).status == DatabaseStatus.queued
