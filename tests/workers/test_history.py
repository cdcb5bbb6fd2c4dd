"""A job's history survives Redis: events are copied to the store as they are published, the
terminal event is there before the status says so, and a publisher that dies after its terminal
event still gets its store records written.

Before: the store got a job's events only at its end, from the Redis stream, so a Redis restarted
without persistence while the job ran lost its first events for good (``queued``, ``started``, the
solutions so far); ``GET /events`` right after the status read ``done`` could lack the terminal
event (the API's reader had not delivered it yet); and a worker that died between its terminal
event and its store writes left the store's record ``running`` for ever.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import redis

from schemas import EventType, JobEvent, JobStatus
from workers.event_archive import BatchArchiver, read_archive
from workers.redis_backend import RedisBackend
from workers.redis_events import Entries, EventPublisher, _Plan
from workers.redis_keys import RedisKeys
from workers.store import Store

from .conftest import GUARD_S, add_database, run, synth, wait_for, worker_thread

KEYS = RedisKeys()


async def _all(backend: RedisBackend, job_id: str) -> list[JobEvent]:
    return await asyncio.wait_for(_follow(backend, job_id), GUARD_S)


async def _follow(backend: RedisBackend, job_id: str) -> list[JobEvent]:
    return [e async for e in backend.events(job_id)]


def test_a_redis_that_loses_its_memory_mid_job_loses_no_history(
    redis_url: str, rclient: redis.Redis, store: Store, tmp_path: Path
) -> None:
    db = add_database(store)
    go = tmp_path / "go"

    async def scenario() -> list[JobEvent]:
        backend = RedisBackend(store, redis_url, block_ms=200)
        backend.reconcile_s, backend.requeue_after_s = 0.1, 0.3
        await backend.start()
        try:
            info, payload = synth(store, db, steps=3, step_s=0.05, go_file=str(go))
            await backend.submit(info, "synth", payload)
            # the job runs (it waits for the go file) and its first events are in the store
            await asyncio.to_thread(
                wait_for,
                lambda: [e.type for e in read_archive(store, info.id)]
                == [EventType.queued, EventType.started],
                GUARD_S,
                0.02,
                "the first events in the store",
            )
            rclient.flushall()  # a restart without persistence: the stream's events 1-2 are gone
            go.touch()
            await _all(backend, info.id)
        finally:
            await backend.close()
        fresh = RedisBackend(store, redis_url, block_ms=200)  # a new API process: nothing in memory
        await fresh.start()
        try:
            return await _all(fresh, info.id)
        finally:
            await fresh.close()

    with worker_thread(redis_url, store, "w1"):
        events = run(scenario())
    assert [e.id for e in events] == list(range(1, len(events) + 1))
    assert [e.type for e in events][:2] == [EventType.queued, EventType.started]
    assert [e.type for e in events].count(EventType.solution) == 3 and events[-1].type == EventType.done
    archived = read_archive(store, events[0].job)
    assert [e.model_dump() for e in archived] == [e.model_dump() for e in events]
    assert store.event_batches(events[0].job) == []  # merged into the whole archive, then removed


def test_the_terminal_event_is_there_once_the_status_says_done(
    redis_url: str, rclient: redis.Redis, store: Store
) -> None:
    """The API follows a job, its stream reader falls behind (stopped here, as a loaded process's
    would lag), a worker ends the job: a client that reads ``done`` then asks for the events gets
    the terminal one."""
    db = add_database(store)

    async def scenario() -> tuple[JobStatus, list[JobEvent]]:
        backend = RedisBackend(store, redis_url, block_ms=200)
        await backend.start()
        try:
            info, payload = synth(store, db)
            await backend.submit(info, "synth", payload)
            assert [e.type for e in await backend.backlog(info.id)] == [EventType.queued]  # followed
            await backend._pump.stop()  # the reader delivers nothing more by itself
            worker = EventPublisher(rclient, store, KEYS)
            worker.publish(info.id, EventType.started, {}, attempt=None)
            worker.publish(info.id, EventType.done, {"result": None}, attempt=None)
            status = (await backend.status(info.id)).status
            return status, await backend.backlog(info.id)
        finally:
            await backend.close()

    status, events = run(scenario())
    assert status == JobStatus.done
    assert [e.type for e in events] == [EventType.queued, EventType.started, EventType.done]


class _DiesAfterPublishing(EventPublisher):
    """A worker killed right after its terminal event's transaction: no store copy written."""

    def _recorded(self, plan: _Plan, entries: Entries | None, unwritten: Any = None) -> None:
        if entries is None:
            super()._recorded(plan, entries, unwritten)


def test_a_publisher_that_dies_after_the_terminal_event_gets_its_records_written(
    redis_url: str, rclient: redis.Redis, store: Store
) -> None:
    db = add_database(store)

    async def scenario() -> str:
        backend = RedisBackend(store, redis_url, block_ms=200)
        backend.reconcile_s, backend.requeue_after_s = 0.1, 0.3
        await backend.start()
        try:
            info, payload = synth(store, db)
            await backend.submit(info, "synth", payload)
            worker = _DiesAfterPublishing(rclient, store, KEYS)
            worker.publish(info.id, EventType.started, {}, attempt=None)
            worker.publish(info.id, EventType.done, {"result": None}, attempt=None)
            await asyncio.to_thread(
                wait_for,
                lambda: store.job_info(info.id).status == JobStatus.done,
                GUARD_S,
                0.05,
                "the record",
            )
            return info.id
        finally:
            await backend.close()

    job_id = run(scenario())
    assert [e.type for e in read_archive(store, job_id)] == [
        EventType.queued,
        EventType.started,
        EventType.done,
    ]
    assert store.events(job_id)  # the whole archive


def test_batches_are_written_on_time_and_handed_over_at_the_end(store: Store) -> None:
    archiver = BatchArchiver(store, flush_s=3600.0)

    def event(i: int, type_: EventType = EventType.progress) -> JobEvent:
        return JobEvent(id=i, job="j1", type=type_, time=float(i), data={})

    for i in (1, 2, 3):
        archiver.add(event(i))
    assert archiver.flush() == 0  # not due yet
    assert archiver.flush(due_only=False) == 1
    assert [e.id for e in read_archive(store, "j1")] == [1, 2, 3]
    archiver.add(event(4))
    assert [e.id for e in archiver.take("j1")] == [4]
    assert archiver.take("j1") == []
    archiver.flush_s = 0.0
    archiver.add(event(5))
    assert archiver.flush() == 1
    assert [e.id for e in read_archive(store, "j1")] == [1, 2, 3, 5]
