"""The Redis backend end to end against a real redis-server, with workers running in threads."""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

import pytest
import redis

from schemas import EventType, JobEvent, JobStatus
from workers.event_archive import read_archive
from workers.redis_backend import RedisBackend
from workers.redis_events import EventPublisher
from workers.redis_keys import RedisKeys
from workers.redis_queue import TAKE_LUA, principal_list
from workers.store import NotFoundError, Store

from .conftest import GUARD_S, add_database, new_job, run, synth, wait_for, worker_thread

KEYS = RedisKeys()


async def collect(
    backend: RedisBackend, job_id: str, after: int = 0, timeout: float = GUARD_S
) -> list[JobEvent]:
    async def go() -> list[JobEvent]:
        return [e async for e in backend.events(job_id, after)]

    return await asyncio.wait_for(go(), timeout)


async def wait_archived(store: Store, job_id: str, count: int, timeout: float = GUARD_S) -> None:
    """Until the store's event archive of a job holds ``count`` events."""
    deadline = time.monotonic() + timeout
    while len(read_archive(store, job_id)) < count:
        assert time.monotonic() < deadline, f"job {job_id}: archive not written within {timeout} s"
        await asyncio.sleep(0.02)


def take_as(client: redis.Redis, consumer: str) -> str:
    """Deliver the next waiting job to ``consumer`` as a worker takes it; its stream entry id."""
    take = client.register_script(TAKE_LUA)
    got = take(keys=[KEYS.queues, KEYS.queues_turn, KEYS.jobs], args=[KEYS.group, consumer])
    assert got, "a job was waiting"
    return str(got[0])


def stream_events(client: redis.Redis, job_id: str) -> list[JobEvent]:
    return [JobEvent.model_validate_json(f["event"]) for _, f in client.xrange(KEYS.events(job_id))]


def test_publisher_ids_contiguous_and_one_terminal(rclient: redis.Redis, store: Store) -> None:
    job = new_job(store, "synth", {"request": {}})
    rclient.set(KEYS.job(job.id), job.model_dump_json())
    pub = EventPublisher(rclient, store, KEYS)
    types = [
        EventType.queued,
        EventType.started,
        EventType.progress,
        EventType.done,
        EventType.failed,
        EventType.progress,
        EventType.cancelled,
    ]
    published = [pub.publish(job.id, t, {"result": "r1"} if t == EventType.done else {}) for t in types]
    assert [e.id if e else None for e in published] == [1, 2, 3, 4, None, None, None]
    events = stream_events(rclient, job.id)
    assert [(e.id, e.type) for e in events] == [(1, "queued"), (2, "started"), (3, "progress"), (4, "done")]
    assert [sid for sid, _ in rclient.xrange(KEYS.events(job.id))] == ["1-0", "2-0", "3-0", "4-0"]
    assert rclient.get(KEYS.terminal(job.id)) == "4"
    assert rclient.ttl(KEYS.events(job.id)) > 0  # finished jobs expire from Redis...
    for info in (store.job_info(job.id), pub.store.job_info(job.id)):  # ...and stay on disk
        assert info.status == JobStatus.done and info.result == "r1" and info.last_event == 4
    archived = [json.loads(line) for line in store.events(job.id)]
    assert [a["id"] for a in archived] == [1, 2, 3, 4]
    # a lost counter (flushed Redis) continues after the last id this publisher saw, never reusing ids
    job2 = new_job(store, "synth", {"request": {}})
    pub.publish(job2.id, EventType.queued, {})
    pub.publish(job2.id, EventType.started, {})
    rclient.flushall()
    assert (e := pub.publish(job2.id, EventType.progress, {})) is not None and e.id == 3


def test_submit_events_done_results(redis_url: str, rclient: redis.Redis, store: Store) -> None:
    db = add_database(store, build=False)

    async def scenario() -> tuple[list[JobEvent], list[JobEvent], str]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            build = new_job(store, "build", {"database": db})
            queued = await backend.submit(build, "build", {"database": db})
            assert queued.id == build.id and queued.last_event >= 1  # a worker may have started it already
            build_events = await collect(backend, build.id)
            job, payload = synth(store, db, steps=3, step_s=0.02)
            await backend.submit(job, "synth", payload)
            # two sockets on one job share one reader
            a, b = await asyncio.gather(collect(backend, job.id), collect(backend, job.id))
            assert a == b
            info = await backend.status(job.id)
            assert info.status == JobStatus.done and info.last_event == a[-1].id
            deadline = time.monotonic() + GUARD_S  # the entry is acked just after the terminal event
            while (health := await backend.health())["pending"] != 0:
                assert time.monotonic() < deadline, f"the entry was not acked within {GUARD_S} s"
                await asyncio.sleep(0.02)
            assert health["workers"] == 1 and health["pending"] == 0 and health["queued"] == 0
            assert health["dead_letters"] == 0 and health["redis"] == "ok"
            return build_events, a, job.id
        finally:
            await backend.close()

    with worker_thread(redis_url, store, "t1"):
        build_events, events, job_id = run(scenario())
    assert [e.type for e in build_events][:2] == ["queued", "started"] and build_events[-1].type == "done"
    assert store.database_info(db).status == "ready"
    assert [e.type for e in events] == ["queued", "started", "solution", "solution", "solution", "done"]
    assert [e.id for e in events] == list(range(1, 7))
    assert events[1].data == {"worker": "t1", "attempt": 1}
    best = events[-1].data["result"]
    assert best == events[-2].data["result"] == "r3"
    assert store.result_report(job_id, best).frames == store.result_motion(job_id, best).num_frames == 12
    assert store.job_info(job_id).status == JobStatus.done  # disk status kept in step
    assert rclient.xlen(KEYS.jobs) == 0  # acked and deleted


def test_resume_after_replays_exactly_the_missed_events(
    redis_url: str, rclient: redis.Redis, store: Store
) -> None:
    db = add_database(store)

    async def scenario() -> None:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            job, payload = synth(store, db, steps=4, step_s=0.05)
            await backend.submit(job, "synth", payload)
            seen: list[JobEvent] = []
            async for event in backend.events(job.id):  # a socket that drops after 3 events
                seen.append(event)
                if len(seen) == 3:
                    break
            rest = await collect(backend, job.id, after=3)  # reconnect with after=3
            assert [e.id for e in seen + rest] == list(range(1, 8)) and rest[-1].type == "done"
            full = seen + rest
        finally:
            await backend.close()
        # another API process (a fresh hub) replays from Redis
        other = RedisBackend(store, redis_url)
        await other.start()
        try:
            assert await collect(other, job.id, after=5) == full[5:]
            assert await collect(other, job.id, after=7) == []
        finally:
            await other.close()
        # Redis forgot the job (retention): status and events come from the store's archive and
        # record, which the worker writes just after publishing the terminal event (in that order)
        await wait_archived(store, job.id, len(full))
        await asyncio.to_thread(wait_for, lambda: store.job_info(job.id).status.finished)
        rclient.delete(KEYS.events(job.id), KEYS.job(job.id))
        third = RedisBackend(store, redis_url)
        await third.start()
        try:
            assert (await third.status(job.id)).status == JobStatus.done
            assert await collect(third, job.id, after=2) == full[2:]
        finally:
            await third.close()
        # events lost everywhere (a partial archive, Redis empty): readers get what there is and
        # return instead of waiting for a terminal event that will never come
        store.put_events(job.id, [e.model_dump_json() for e in full[:3]])
        fourth = RedisBackend(store, redis_url)
        fourth.quiet_check_s = 0.2
        await fourth.start()
        try:
            assert await collect(fourth, job.id, after=1) == full[1:3]
        finally:
            await fourth.close()

    with worker_thread(redis_url, store, "t1"):
        run(scenario())


def test_cancel_mid_search_returns_best_so_far(redis_url: str, store: Store) -> None:
    db = add_database(store)

    async def scenario() -> list[JobEvent]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            # two solutions, then it waits for the cancel (120 s: a hang guard), so the solutions
            # are exactly those seen however long the cancel takes to reach the engine
            job, payload = synth(store, db, steps=200, step_s=0.03, hold_after=2, budget_s=120)
            await backend.submit(job, "synth", payload)
            events: list[JobEvent] = []
            async for event in backend.events(job.id):
                events.append(event)
                if sum(e.type == EventType.solution for e in events) == 2:
                    await backend.cancel(job.id)
            info = await backend.status(job.id)
            assert info.status == JobStatus.cancelled and info.result == events[-1].data["result"]
            return events
        finally:
            await backend.close()

    with worker_thread(redis_url, store, "t1"):
        events = run(scenario())
    solutions = [e for e in events if e.type == EventType.solution]
    assert events[-1].type == EventType.cancelled and len(solutions) == 2
    best = min(solutions, key=lambda e: e.data["score"])
    assert events[-1].data["result"] == best.data["result"] == solutions[-1].data["result"]


def test_cancel_queued_job_ends_at_once_and_is_skipped(
    redis_url: str, rclient: redis.Redis, store: Store
) -> None:
    db = add_database(store)

    async def scenario() -> list[JobEvent]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            job, payload = synth(store, db, steps=2, step_s=0.01)
            await backend.submit(job, "synth", payload)
            assert (await backend.cancel(job.id)).status == JobStatus.cancelled
            assert (await backend.cancel(job.id)).status == JobStatus.cancelled  # idempotent
            return await collect(backend, job.id)
        finally:
            await backend.close()

    events = run(scenario())
    assert [(e.id, e.type) for e in events] == [(1, "queued"), (2, "cancelled")]
    with worker_thread(redis_url, store, "t1"):
        wait_for(lambda: rclient.xlen(KEYS.jobs) == 0, what="the worker to drop the cancelled job")
    assert [e.type for e in stream_events(rclient, events[0].job)] == ["queued", "cancelled"]


def test_submit_is_idempotent_and_unknown_jobs_raise(
    redis_url: str, rclient: redis.Redis, store: Store
) -> None:
    async def scenario() -> None:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            job, payload = synth(store, "nodb")
            first = await backend.submit(job, "synth", payload)
            again = await backend.submit(job, "synth", payload)
            assert first == again and rclient.llen(principal_list(KEYS, None)) == 1
            assert [e.type for e in stream_events(rclient, job.id)] == ["queued"]
            with pytest.raises(NotFoundError):
                await backend.status("nosuchjob")
            with pytest.raises(NotFoundError):
                await backend.status("../etc")
            health = await backend.health()
            assert health["queued"] == 1 and health["workers"] == 0
        finally:
            await backend.close()

    run(scenario())


def test_failed_job_and_dead_letter_after_max_deliveries(
    redis_url: str, rclient: redis.Redis, store: Store
) -> None:
    db = add_database(store)

    async def submit(payload: dict[str, Any], kind: str = "synth") -> str:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            job = new_job(store, kind, payload)
            await backend.submit(job, kind, payload)
            return job.id
        finally:
            await backend.close()

    doomed = run(submit({"request": {"engine": "scripted", "database": db, "steps": 2}}))
    # a worker "ghost" took it and died; it was already redelivered once (2 deliveries so far)
    entry_id = take_as(rclient, "ghost")
    rclient.xclaim(KEYS.jobs, KEYS.group, "ghost", 0, [entry_id], retrycount=2)
    failing = run(submit({"request": {"engine": "scripted", "database": db, "steps": 3, "fail_at": 1}}))
    rclient.xadd(KEYS.jobs, {"job": "x", "kind": "synth"})  # malformed: no payload
    with worker_thread(redis_url, store, "t1", max_deliveries=2):
        wait_for(
            lambda: rclient.xlen(KEYS.jobs) == 0 and not rclient.xpending(KEYS.jobs, KEYS.group)["pending"],
            what="the queue to drain",
        )
    dead = [fields for _, fields in rclient.xrange(KEYS.dead)]
    assert [(d.get("job"), d["deliveries"]) for d in dead] == [(doomed, "3"), ("x", "1")]
    assert "delivered 3 times" in dead[0]["reason"] and "malformed" in dead[1]["reason"]
    events = stream_events(rclient, doomed)
    assert [e.type for e in events] == ["queued", "failed"]
    assert events[-1].data["error"]["code"] == "dead_letter"
    assert store.job_info(doomed).status == JobStatus.failed
    events = stream_events(rclient, failing)
    assert [e.type for e in events] == ["queued", "started", "solution", "failed"]
    assert events[-1].data["error"]["code"] == "invalid_request"


def test_build_lock_two_builds_of_one_database_build_once(
    redis_url: str, rclient: redis.Redis, store: Store
) -> None:
    db = add_database(store, build=False)
    # a stale lock from a worker that died (no heartbeat) does not hold builds up for its TTL
    rclient.set(KEYS.build_lock(db), "ghost/job/0", ex=600)

    async def scenario() -> list[list[JobEvent]]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            jobs = [new_job(store, "build", {"database": db}) for _ in range(2)]
            for job in jobs:
                await backend.submit(job, "build", {"database": db})
            return list(await asyncio.gather(*(collect(backend, j.id) for j in jobs)))
        finally:
            await backend.close()

    with worker_thread(redis_url, store, "t1"), worker_thread(redis_url, store, "t2"):
        results = run(scenario())
    finals = [events[-1] for events in results]
    assert [e.type for e in finals] == ["done", "done"]
    assert sorted(bool(e.data.get("reused")) for e in finals) == [False, True]
    assert store.database_info(db).status == "ready" and not rclient.exists(KEYS.build_lock(db))


def test_reclaim_hung_worker_and_own_leftovers(redis_url: str, rclient: redis.Redis, store: Store) -> None:
    db = add_database(store)

    async def submit_two() -> list[str]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            ids = []
            for _ in range(2):
                job, payload = synth(store, db, steps=1, step_s=0.0)
                await backend.submit(job, "synth", payload)
                ids.append(job.id)
            return ids
        finally:
            await backend.close()

    hung, leftover = run(submit_two())
    # "zombie" beats but has not touched its entry for a minute (hung); "t1" is a previous process
    # with the name of the worker about to start, which left an entry behind
    rclient.set(KEYS.worker("zombie"), "{}", ex=60)
    for consumer in ("zombie", "t1"):
        entry_id = take_as(rclient, consumer)
        if consumer == "zombie":
            rclient.xclaim(KEYS.jobs, KEYS.group, "zombie", 0, [entry_id], idle=60_000, justid=True)
    with worker_thread(redis_url, store, "t1"):
        wait_for(lambda: all(rclient.exists(KEYS.terminal(j)) for j in (hung, leftover)), what="both jobs")
    for job_id in (hung, leftover):
        events = stream_events(rclient, job_id)
        assert events[-1].type == EventType.done
        assert [e.data for e in events if e.type == EventType.started] == [{"worker": "t1", "attempt": 2}]


def test_delete_a_finished_job_refuse_a_running_one(
    redis_url: str, rclient: redis.Redis, store: Store
) -> None:
    """``DELETE /v1/jobs/{id}`` on the Redis backend: a finished job goes from Redis and the store;
    a running one is refused (cancel it first)."""
    from workers.backend import JobNotFinished

    db = add_database(store)

    async def scenario() -> tuple[str, str]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            job, payload = synth(store, db, steps=2, step_s=0)
            await backend.submit(job, "synth", payload)
            assert (await collect(backend, job.id))[-1].type == "done"
            long, long_payload = synth(store, db, steps=500, step_s=0.05)
            await backend.submit(long, "synth", long_payload)
            with pytest.raises(JobNotFinished):
                await backend.delete(long.id)
            await backend.delete(job.id)
            with pytest.raises(NotFoundError):
                await backend.status(job.id)
            with pytest.raises(NotFoundError):
                await backend.delete(job.id)
            await backend.cancel(long.id)
            assert (await collect(backend, long.id))[-1].type == "cancelled"
            await backend.delete(long.id)
            return job.id, long.id
        finally:
            await backend.close()

    with worker_thread(redis_url, store, "t1"):
        ids = run(scenario())
    for job_id in ids:
        assert store.objects.list(f"jobs/{job_id}") == []
        assert not rclient.exists(KEYS.job(job_id), KEYS.events(job_id), KEYS.event_seq(job_id))
