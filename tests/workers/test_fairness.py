"""Fair scheduling: one principal's backlog never keeps another principal's next job waiting
longer than the job each worker is running, on both backends.

Before: one first-in-first-out queue, so bob's one job started after all of alice's queued jobs
(256 of them kept it ``queued`` for over a minute). The tests check the order of the starts, not
their times: with one worker busy on alice's job, alice's backlog queued, then bob's job, bob's
job is the next to start.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
import redis

from schemas import EventType, JobEvent, JobInfo
from workers.embedded import EmbeddedBackend
from workers.fair_queue import FairQueue
from workers.redis_backend import RedisBackend
from workers.store import Store

from .conftest import GUARD_S, add_database, run, synth, wait_for, worker_thread


def test_the_fair_queue_serves_principals_in_turn() -> None:
    queue: FairQueue[tuple[str, int]] = FairQueue(lambda item: item[0])
    for i in range(4):
        queue.append(("alice", i))
    queue.append(("bob", 0))
    queue.append(("bob", 1))
    queue.append((None, 0))  # type: ignore[arg-type]  # no owner: a line of its own
    order = [queue.pop() for _ in range(len(queue))]
    # a principal new to the turn goes first (never served): the last to queue is served first
    assert order == [
        (None, 0),
        ("bob", 0),
        ("alice", 0),
        ("bob", 1),
        ("alice", 1),
        ("alice", 2),
        ("alice", 3),
    ]
    assert not queue
    # alice was served last: bob's next job goes before her next one, whoever queued first
    queue.append(("alice", 4))
    queue.append(("bob", 2))
    assert queue.pop() == ("bob", 2)
    item = queue.pop()
    queue.unpop(item)  # not started after all: first again
    assert queue.pop() == ("alice", 4)
    queue.append(("carol", 0))
    queue.remove(("carol", 0))
    with pytest.raises(IndexError):
        queue.pop()


def _owned(info: JobInfo, owner: str) -> JobInfo:
    return info.model_copy(update={"owner": owner})


async def _started_order(backend: EmbeddedBackend | RedisBackend, jobs: list[str]) -> list[str]:
    """The jobs in the order they started (their ``started`` events' times; one worker runs them
    one after the other)."""

    async def events(job_id: str) -> list[JobEvent]:
        return [e async for e in backend.events(job_id)]

    logs = await asyncio.wait_for(asyncio.gather(*(events(j) for j in jobs)), GUARD_S)
    assert all(log[-1].type == EventType.done for log in logs)
    started = {log[0].job: next(e.time for e in log if e.type == EventType.started) for log in logs}
    return sorted(jobs, key=lambda j: started[j])


async def _scenario(
    backend: EmbeddedBackend | RedisBackend, store: Store, db: str, go: Path
) -> tuple[list[str], list[str], str]:
    """alice's job holds the only worker; alice queues 5 more, then bob 1; the hold ends."""
    blocker, payload = synth(store, db, steps=1, step_s=0.0, go_file=str(go))
    await backend.submit(_owned(blocker, "alice"), "synth", payload)
    await asyncio.to_thread(
        wait_for, lambda: store.job_info(blocker.id).status.value == "running", GUARD_S, 0.02, "the blocker"
    )
    backlog = []
    for _ in range(5):
        info, payload = synth(store, db, steps=1, step_s=0.0)
        await backend.submit(_owned(info, "alice"), "synth", payload)
        backlog.append(info.id)
    bobs, payload = synth(store, db, steps=1, step_s=0.0)
    await backend.submit(_owned(bobs, "bob"), "synth", payload)
    go.touch()
    order = await _started_order(backend, [blocker.id, *backlog, bobs.id])
    return order, backlog, bobs.id


def test_embedded_another_principals_job_starts_next(store: Store, tmp_path: Path) -> None:
    db = add_database(store)

    async def scenario() -> tuple[list[str], list[str], str]:
        backend = EmbeddedBackend(store, 1)
        await backend.start()
        try:
            return await _scenario(backend, store, db, tmp_path / "go")
        finally:
            await backend.close()

    order, backlog, bob = run(scenario())
    assert order[1] == bob, "bob's job waited for alice's backlog"
    assert order[2:] == backlog  # alice's own jobs keep their order


def test_redis_another_principals_job_starts_next(
    redis_url: str, rclient: redis.Redis, store: Store, tmp_path: Path
) -> None:
    db = add_database(store)

    async def scenario() -> tuple[list[str], list[str], str]:
        backend = RedisBackend(store, redis_url, block_ms=200)
        await backend.start()
        try:
            return await _scenario(backend, store, db, tmp_path / "go")
        finally:
            await backend.close()

    with worker_thread(redis_url, store, "w1"):
        order, backlog, bob = run(scenario())
    assert order[1] == bob, "bob's job waited for alice's backlog"
    assert order[2:] == backlog
