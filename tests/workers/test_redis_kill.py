"""Worker processes that die: SIGKILL mid-job loses nothing; SIGTERM finishes the job first.

The bar: 2 workers, 20 jobs, one worker SIGKILLed mid-run → 20 done, 0 lost, 0 duplicated results.
"""

from __future__ import annotations

import asyncio
import signal

import pytest
import redis

from schemas import EventType, JobEvent, JobStatus
from workers.redis_backend import RedisBackend
from workers.redis_keys import RedisKeys
from workers.store import Store

from .conftest import GUARD_S, add_database, run, synth, wait_for, worker_processes

pytestmark = pytest.mark.slow  # tests/run.sh runs these with CI=true or SEGUE_SLOW=1

KEYS = RedisKeys()


def stream_events(client: redis.Redis, job_id: str) -> list[JobEvent]:
    return [JobEvent.model_validate_json(f["event"]) for _, f in client.xrange(KEYS.events(job_id))]


def job_of(client: redis.Redis, consumer: str) -> str | None:
    """The job a worker holds (pending entry), if any."""
    for p in client.xpending_range(KEYS.jobs, KEYS.group, "-", "+", 10, consumername=consumer):
        entries = client.xrange(KEYS.jobs, p["message_id"], p["message_id"])
        if entries:
            return str(entries[0][1]["job"])
    return None


def test_sigkill_mid_job_two_workers_twenty_jobs(redis_url: str, rclient: redis.Redis, store: Store) -> None:
    db = add_database(store)
    with worker_processes(redis_url, store, ["w1", "w2"]) as procs:
        wait_for(lambda: all(rclient.exists(KEYS.worker(n)) for n in procs), what="both workers to start")

        async def scenario() -> tuple[list[str], str, bool]:
            backend = RedisBackend(store, redis_url)
            await backend.start()
            try:
                jobs = []
                for _ in range(20):
                    job, payload = synth(store, db, steps=4, step_s=0.1)
                    await backend.submit(job, "synth", payload)
                    jobs.append(job.id)

                def victim_mid_job() -> str | None:  # mid-run: some jobs done, w1 inside one
                    if sum(bool(rclient.exists(KEYS.terminal(j))) for j in jobs) < 6:
                        return None
                    job_id = job_of(rclient, "w1")
                    # one solution of four so far: at least two 0.1 s steps still to run
                    if (
                        job_id
                        and sum(e.type == EventType.solution for e in stream_events(rclient, job_id)) == 1
                    ):
                        return job_id
                    return None

                killed = await asyncio.to_thread(wait_for, victim_mid_job, GUARD_S, 0.01, "w1 mid-job")
                procs["w1"].send_signal(signal.SIGKILL)
                procs["w1"].wait(timeout=GUARD_S)
                # on a loaded machine w1 may still have finished the job before the signal landed
                finished_first = bool(rclient.exists(KEYS.terminal(killed)))

                async def final(job_id: str) -> JobEvent:
                    return [e async for e in backend.events(job_id)][-1]

                finals = await asyncio.wait_for(asyncio.gather(*(final(j) for j in jobs)), GUARD_S)
                assert [e.type for e in finals] == [EventType.done] * 20
                return jobs, killed, finished_first
            finally:
                await backend.close()

        jobs, killed, finished_first = run(scenario())
        for job_id in jobs:
            events = stream_events(rclient, job_id)
            assert [e.id for e in events] == list(range(1, len(events) + 1)), "event ids must be contiguous"
            terminals = [e for e in events if e.type.terminal]
            assert len(terminals) == 1 and terminals[0] is events[-1] and terminals[0].type == EventType.done
            assert store.job_info(job_id).status == JobStatus.done
            assert store.result_report(job_id, terminals[0].data["result"]).score == 1.0
        starts = [e for e in stream_events(rclient, killed) if e.type == EventType.started]
        ran_twice = [j for j in jobs if sum(e.type == "started" for e in stream_events(rclient, j)) > 1]
        if finished_first:
            assert [s.data["worker"] for s in starts] == ["w1"] and ran_twice == []
        else:
            assert [s.data["worker"] for s in starts] == ["w1", "w2"] and starts[-1].data["attempt"] == 2
            assert ran_twice == [killed]
        wait_for(lambda: rclient.xlen(KEYS.jobs) == 0, what="every entry acked and deleted")
        assert rclient.xpending(KEYS.jobs, KEYS.group)["pending"] == 0 and rclient.xlen(KEYS.dead) == 0
        assert procs["w2"].poll() is None


def test_sigterm_finishes_the_current_job_then_exits(
    redis_url: str, rclient: redis.Redis, store: Store
) -> None:
    db = add_database(store)
    # a heartbeat TTL far longer than the test: the worker's key can only go by its own goodbye
    with worker_processes(redis_url, store, ["w1"], heartbeat_ttl_s="600") as procs:
        wait_for(lambda: rclient.exists(KEYS.worker("w1")), what="the worker to start")

        async def scenario() -> list[JobEvent]:
            backend = RedisBackend(store, redis_url)
            await backend.start()
            try:
                job, payload = synth(store, db, steps=5, step_s=0.1)
                await backend.submit(job, "synth", payload)
                events = []
                async for event in backend.events(job.id):
                    events.append(event)
                    if event.type == EventType.started:
                        procs["w1"].send_signal(signal.SIGTERM)
                return events
            finally:
                await backend.close()

        events = run(scenario())
        assert events[-1].type == EventType.done and len([e for e in events if e.type == "solution"]) == 5
        assert procs["w1"].wait(timeout=GUARD_S) == 0  # exits by itself (a worker that stays is a hang)
        assert not rclient.exists(KEYS.worker("w1"))  # gone at once, not after the TTL
