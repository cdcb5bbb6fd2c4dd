"""At-least-once for real (issue 17): Redis losing its memory, Redis down at submission, a busy engine
that would starve a heartbeat thread, and the supervisor's cancel, time and memory limits."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest
import redis

from schemas import EventType, JobEvent
from schemas.jobs import JobKind
from service.errors import ApiError
from service.jobs_common import submit_job
from service.metrics import Metrics
from workers.redis_backend import RedisBackend
from workers.store import Store
from workers.supervisor import ChildConfig, EngineProcess, Task, engine_plugins

from .conftest import GUARD_S, _free_port, add_database, run, synth, wait_for, worker_thread


async def _collect(backend: Any, job_id: str, timeout: float = GUARD_S) -> list[JobEvent]:
    async def go() -> list[JobEvent]:
        return [e async for e in backend.events(job_id)]

    return await asyncio.wait_for(go(), timeout)


def test_jobs_redis_forgets_are_queued_again(redis_url: str, rclient: redis.Redis, store: Store) -> None:
    """FLUSHALL is what a restart without persistence leaves: the store's record brings the job back."""
    db = add_database(store)

    async def scenario() -> list[JobEvent]:
        backend = RedisBackend(store, redis_url, block_ms=200)
        backend.reconcile_s, backend.requeue_after_s = 0.1, 0.3
        await backend.start()
        try:
            info, payload = synth(store, db, steps=2, step_s=0.01)
            await backend.submit(info, "synth", payload)
            rclient.flushall()  # no worker has run it yet: the queue and its events are gone
            with worker_thread(redis_url, store, "w1"):
                return await _collect(backend, info.id)
        finally:
            await backend.close()

    events = run(scenario())
    assert events[-1].type == EventType.done
    assert [e.id for e in events] == list(range(1, len(events) + 1))  # no id reused after the loss


def test_submission_while_redis_is_down_is_503_and_stores_nothing(tmp_path: Path) -> None:
    store = Store(tmp_path)
    dead = f"redis://127.0.0.1:{_free_port()}/0"

    async def scenario() -> tuple[int, dict[str, Any]]:
        backend = RedisBackend(store, dead, block_ms=200)
        await backend.start()  # starts anyway: Redis may come up later
        try:
            with pytest.raises(ApiError) as refused:
                await submit_job(store, backend, Metrics(), JobKind.synth, {"request": {}}, engine="clip")
            return refused.value.status, await backend.health()
        finally:
            await backend.close()

    status, health = run(scenario())
    assert status == 503
    assert store.list_jobs() == []  # no ghost record
    assert "error" in health and health["redis"] == "unreachable"


def test_a_busy_engine_cannot_starve_the_heartbeat(
    redis_url: str, rclient: redis.Redis, store: Store
) -> None:
    """An engine holding the GIL for longer than the idle backstop: the job still runs exactly once,
    because the engine runs in a child process and the worker's threads keep refreshing its entry."""
    db = add_database(store)
    backend_events: list[JobEvent] = []

    async def scenario() -> None:
        backend = RedisBackend(store, redis_url, block_ms=200)
        await backend.start()
        try:
            info, payload = synth(store, db, steps=2, step_s=0.0, spin_s=6.0)
            await backend.submit(info, "synth", payload)
            backend_events.extend(await _collect(backend, info.id))
        finally:
            await backend.close()

    # the engine spins 6 s, past the 4-s idle backstop; the entry is refreshed every 0.2 s, so only
    # a stall of this process of nearly 4 s could let w2 take the job (1 s did, with a 1-s backstop)
    with (
        worker_thread(redis_url, store, "w1", reclaim_idle_s=4.0),
        worker_thread(redis_url, store, "w2", reclaim_idle_s=4.0),
    ):
        run(scenario())
    assert backend_events[-1].type == EventType.done
    assert [e.type for e in backend_events].count(EventType.started) == 1


def _supervised(store: Store, **kwargs: Any) -> tuple[EngineProcess, list[tuple[str, Any]]]:
    seen: list[tuple[str, Any]] = []
    process = EngineProcess(
        "t",
        ChildConfig(store_root=store.url, plugins=engine_plugins()),
        lambda task, type_, data, when: seen.append((type_.value, data)),
        lambda task, outcome, detail: seen.append(("end", outcome)),
        **kwargs,
    )
    process.start()
    assert process.ready.wait(GUARD_S)
    return process, seen


@pytest.mark.parametrize("limit", ["cancel", "time"])
def test_the_supervisor_kills_a_job_that_does_not_stop(store: Store, limit: str) -> None:
    db = add_database(store)
    process, seen = _supervised(store, cancel_grace_s=0.5)
    try:
        # the engine would spin (ignoring the cancel) for 60 s, then end "done": only a kill by the
        # supervisor ends it with the outcome below, whatever the machine's load
        payload = {"request": {"engine": "scripted", "database": db, "steps": 1, "spin_s": 60.0}}
        task = Task("j1", "synth", payload, time_limit_s=1.0 if limit == "time" else None)
        assert process.run(task)
        wait_for(lambda: any(t == "started" for t, _ in seen))
        if limit == "cancel":
            process.cancel("j1")
        wait_for(lambda: any(t == "end" for t, _ in seen))
        assert [d for t, d in seen if t == "end"] == ["cancel_timeout" if limit == "cancel" else "time_limit"]
        wait_for(lambda: process.idle, what="a fresh engine process")  # replaced at once
        assert process.restarts == 1
    finally:
        process.close()


def test_the_supervisor_stops_a_job_over_its_memory(store: Store) -> None:
    db = add_database(store)
    process, seen = _supervised(store, max_rss_bytes=1)  # any process is over one byte
    try:
        # the engine waits for a file that never comes (120-s hang guard): stopped by the limit alone
        never = str(store.root / "never")
        request = {"engine": "scripted", "database": db, "steps": 1, "go_file": never, "budget_s": 120}
        assert process.run(Task("j1", "synth", {"request": request}))
        wait_for(lambda: any(t == "end" for t, _ in seen))
        assert ("end", "memory_limit") in seen
    finally:
        process.close()
