"""Fenced attempts with real processes and a real redis-server: a worker that hangs (SIGSTOP) past
the reclaim time loses its job to a second worker's attempt 2, and once resumed (SIGCONT) publishes
nothing and writes no result: the job ends once, and every event after the last ``started``
carries that start's attempt."""

from __future__ import annotations

import asyncio
import os
import signal
from pathlib import Path

import pytest
import redis

from motion import parse_bvh
from motion.samples import sample_path
from schemas import EventType, JobEvent, JobStatus, Report
from tests.processes import engine_children
from workers.fencing import Fence, FencedStore, StaleAttempt
from workers.redis_backend import RedisBackend
from workers.redis_events import EventPublisher
from workers.redis_keys import RedisKeys
from workers.store import Store

from .conftest import GUARD_S, add_database, run, spawn_worker, synth, wait_for

KEYS = RedisKeys()


def stream_events(client: redis.Redis, job_id: str) -> list[JobEvent]:
    return [JobEvent.model_validate_json(f["event"]) for _, f in client.xrange(KEYS.events(job_id))]


def running_job(client: redis.Redis, worker: str) -> str | None:
    """The job a worker's heartbeat names (None when idle or silent)."""
    import json

    raw = client.get(KEYS.worker(worker))
    return json.loads(raw).get("job") if raw else None


def test_publisher_refuses_a_stale_attempt_and_stamps_events(rclient: redis.Redis, store: Store) -> None:
    """Unit level: attempt 1 publishes until attempt 2 takes the key; the API's attempt-0 events are
    refused once a run started; every event carries its attempt."""
    db = add_database(store)
    job, _ = synth(store, db)
    publisher = EventPublisher(rclient, store, KEYS)
    assert publisher.publish(job.id, EventType.queued, {}, attempt=0) is not None
    rclient.set(KEYS.attempt(job.id), 1)
    assert publisher.publish(job.id, EventType.started, {"attempt": 1}, attempt=1) is not None
    with pytest.raises(StaleAttempt):
        publisher.publish(job.id, EventType.cancelled, {"result": None}, attempt=0)
    rclient.set(KEYS.attempt(job.id), 2)
    with pytest.raises(StaleAttempt):
        publisher.publish(job.id, EventType.progress, {"fraction": 0.5, "message": ""}, attempt=1)
    assert publisher.publish(job.id, EventType.started, {"attempt": 2}, attempt=2) is not None
    assert publisher.publish(job.id, EventType.failed, {"error": {"message": "x"}}, attempt=None)
    events = stream_events(rclient, job.id)
    assert [(e.id, e.type.value, e.attempt) for e in events] == [
        (1, "queued", 0),
        (2, "started", 1),
        (3, "started", 2),
        (4, "failed", 2),
    ]
    assert store.job_info(job.id).attempt == 2


@pytest.mark.slow
@pytest.mark.parametrize("frozen", ["worker", "worker_and_engine"])
def test_a_hung_worker_resumed_publishes_nothing(
    redis_url: str, rclient: redis.Redis, store: Store, tmp_path: Path, frozen: str
) -> None:
    db = add_database(store)
    w1_log = tmp_path / "w1.log"
    opts = {"reclaim_idle_s": "2", "log_level": "WARNING"}
    w1 = spawn_worker(redis_url, store, "w1", log=w1_log, **opts)
    procs = [w1]
    stopped: list[int] = []
    try:
        wait_for(lambda: rclient.exists(KEYS.worker("w1")), what="w1 to start")

        async def submit() -> str:
            backend = RedisBackend(store, redis_url)
            await backend.start()
            try:
                job, payload = synth(store, db, steps=60, step_s=0.1)
                await backend.submit(job, "synth", payload)
                return job.id
            finally:
                await backend.close()

        job_id = run(submit())
        wait_for(
            lambda: sum(e.type == EventType.solution for e in stream_events(rclient, job_id)) >= 2,
            what="w1's first solutions",
        )
        stopped = [w1.pid] + (engine_children(w1.pid) if frozen == "worker_and_engine" else [])
        for pid in stopped:
            os.kill(pid, signal.SIGSTOP)
        procs.append(spawn_worker(redis_url, store, "w2", **opts))

        def second_start() -> JobEvent | None:
            starts = [e for e in stream_events(rclient, job_id) if e.type == EventType.started]
            return starts[-1] if len(starts) == 2 else None

        start2 = wait_for(second_start, what="w2 to run attempt 2")
        assert start2.data == {"worker": "w2", "attempt": 2} and start2.attempt == 2
        for pid in stopped:
            os.kill(pid, signal.SIGCONT)
        stopped = []
        wait_for(lambda: rclient.exists(KEYS.terminal(job_id)), what="the job's end")
        wait_for(lambda: running_job(rclient, "w1") is None, what="w1 to drop its stale run")
        wait_for(lambda: rclient.xlen(KEYS.jobs) == 0, what="the entry acked and deleted")
    finally:
        for pid in stopped:
            os.kill(pid, signal.SIGCONT)
        for proc in procs:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=GUARD_S)

    events = stream_events(rclient, job_id)
    assert [e.id for e in events] == list(range(1, len(events) + 1))
    terminals = [e for e in events if e.type.terminal]
    assert len(terminals) == 1 and terminals[0] is events[-1] and terminals[0].type == EventType.done
    last_start = max(i for i, e in enumerate(events) if e.type == EventType.started)
    assert {e.attempt for e in events[last_start:]} == {2}
    assert [e.attempt for e in events] == sorted(e.attempt for e in events)  # attempt 1 never after 2
    assert str(terminals[0].data["result"]).startswith("a2r")
    info = store.job_info(job_id)
    assert info.status == JobStatus.done and info.attempt == 2 and info.result == terminals[0].data["result"]
    # attempt 1 wrote no result once attempt 2 held the job, and it said it stopped
    results = store.objects.local_path(f"jobs/{job_id}/results")  # the test's store is a directory
    assert results is not None
    late = [p.name for p in results.glob("r*.json") if p.stat().st_mtime > start2.time]
    assert late == []
    text = w1_log.read_text(errors="replace")
    assert "attempt 1 lost the job" in text and "publishes nothing more" in text


def test_a_result_written_while_the_run_lost_its_job_is_removed(
    rclient: redis.Redis, store: Store, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Attempt 2 takes the job between attempt 1's check and its write (or while attempt 1's process
    is stopped there): the result is checked again once written and removed, and the write refused;
    a write while the run holds its job stays."""
    job_id, key = "f" * 32, KEYS.attempt("f" * 32)
    fenced = FencedStore(store.objects)
    motion = parse_bvh(sample_path("walk").read_bytes()).slice(0, 10)
    report = Report(job=job_id, result="r1", engine="x", score=0.0, frames=10, fps=motion.fps, provenance=[])
    rclient.set(key, 1)
    fenced.fence = Fence(rclient, key, job_id, 1)
    fenced.put_result(job_id, "r1", motion, report)  # held: written
    write = Store.put_result

    def taken_meanwhile(self: Store, *args: object) -> None:
        write(self, *args)  # type: ignore[arg-type]
        rclient.set(key, 2)  # attempt 2 took the job while attempt 1 wrote

    monkeypatch.setattr(Store, "put_result", taken_meanwhile)
    with pytest.raises(StaleAttempt):
        fenced.put_result(job_id, "r2", motion, report)
    assert sorted(store.objects.list(f"jobs/{job_id}/results")) == [
        f"jobs/{job_id}/results/r1.json",
        f"jobs/{job_id}/results/r1.npz",
    ]
    assert store.result_report(job_id, "r1") == report


def test_an_api_cancel_while_queued_is_refused_once_a_run_started(redis_url: str, store: Store) -> None:
    """The queued-cancel race: the API's ``cancelled`` (attempt 0) is refused when a run took the
    job meanwhile; the cancel flag it set ends the run instead (here: no worker, so it stays)."""
    db = add_database(store)

    async def scenario() -> tuple[list[JobEvent], str | None]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            job, payload = synth(store, db)
            await backend.submit(job, "synth", payload)
            client = redis.Redis.from_url(redis_url, decode_responses=True)
            client.set(KEYS.attempt(job.id), 1)  # a run took it between the status read and the publish
            info = await backend.status(job.id)
            await backend._cancel(*backend._redis(), info)
            flag = client.get(KEYS.cancel(job.id))
            events = stream_events(client, job.id)
            client.close()
            return events, flag
        finally:
            await backend.close()

    events, flag = asyncio.run(scenario())
    assert [e.type for e in events] == [EventType.queued] and flag == "1"
