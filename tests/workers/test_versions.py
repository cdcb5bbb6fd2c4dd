"""A worker of another version than the API refuses its jobs, with a clear log, and leaves them
queued for a worker of the right version.

"Version" is the job format (:data:`workers.version.JOB_FORMAT`) and the package version; the API
stamps both on every job it queues. Before: any worker ran any job it could read.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
import redis

from schemas import EventType, JobEvent
from workers import version
from workers.redis_backend import RedisBackend
from workers.redis_keys import RedisKeys
from workers.store import Store

from .conftest import GUARD_S, add_database, run, spawn_worker, synth, wait_for, worker_thread

pytestmark = pytest.mark.slow

KEYS = RedisKeys()


def stream_events(client: redis.Redis, job_id: str) -> list[JobEvent]:
    return [JobEvent.model_validate_json(f["event"]) for _, f in client.xrange(KEYS.events(job_id))]


def test_a_worker_of_another_version_refuses_the_job(
    redis_url: str, rclient: redis.Redis, store: Store, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    installed = version.package_version()
    monkeypatch.setattr(version, "package_version", lambda: "9.9.9")  # this API (and its thread worker)
    db = add_database(store)
    log = tmp_path / "old-worker.log"
    old = spawn_worker(redis_url, store, "old", log=log)  # the installed version, in its own process
    try:

        async def scenario() -> tuple[list[JobEvent], dict[str, str]]:
            backend = RedisBackend(store, redis_url, block_ms=200)
            await backend.start()
            try:
                info, payload = synth(store, db, steps=1, step_s=0.0)
                await backend.submit(info, "synth", payload)
                refused = f"worker old refuses job {info.id}"
                await asyncio.to_thread(
                    wait_for, lambda: refused in log.read_text(), GUARD_S, 0.05, "the old worker's refusal"
                )
                assert [e.type for e in stream_events(rclient, info.id)] == [EventType.queued]
                versions = (await backend.health())["worker_versions"]
                with worker_thread(redis_url, store, "new"):  # the API's version: it runs the job
                    events = [e async for e in backend.events(info.id)]
                return events, versions
            finally:
                await backend.close()

        events, versions = run(asyncio.wait_for(scenario(), 2 * GUARD_S))
    finally:
        old.kill()
        old.wait(timeout=GUARD_S)
    assert events[-1].type == EventType.done
    assert [e.data["worker"] for e in events if e.type == EventType.started] == ["new"]
    text = log.read_text()
    assert f"it was queued by an API of segue 9.9.9, job format {version.JOB_FORMAT}" in text
    assert f"this worker is segue {installed}, job format {version.JOB_FORMAT}" in text
    assert "run workers of the API's version" in text
    assert versions["old"] == f"segue {installed}, job format {version.JOB_FORMAT}"
