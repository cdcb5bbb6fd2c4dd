"""The embedded backend end to end: builds, synthesis, cancellation, resume, worker loss."""

from __future__ import annotations

import asyncio
import os
import uuid
from pathlib import Path
from typing import Any

import pytest

from engines.registry import load_plugins, parse_database_spec
from motion.samples import sample_path
from schemas import DatabaseInfo, DatabaseStatus, EventType, JobEvent, JobInfo, JobStatus
from schemas.databases import database_id
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
            # cancel an anytime search mid-way: cancelled, with the best result so far (it holds
            # after 3 solutions until the cancel arrives, however long that takes: 120 s hang guard)
            request = {"engine": "scripted", "database": db, "steps": 50, "step_s": 0.05}
            slow = await _submit(
                backend, store, "synth", {"request": request | {"hold_after": 3, "budget_s": 120}}
            )
            seen: list[JobEvent] = []
            async for event in backend.events(slow):
                seen.append(event)
                if event.type == EventType.solution and event.data["result"] == "r3":
                    await backend.cancel(slow)
            assert seen[-1].type == EventType.cancelled
            best = seen[-1].data["result"]
            assert [e.data["result"] for e in seen if e.type == EventType.solution] == ["r1", "r2", "r3"]
            assert best == "r3"
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


def test_jobs_left_unfinished_by_a_dead_server_run_again_at_start(tmp_path: Path) -> None:
    """The store is the truth: a job a dead server left ``running`` is queued again by the next one,
    its events continuing where the old ones stopped (clients resume with ``after=``)."""

    async def first() -> str:
        backend = EmbeddedBackend(Store(tmp_path), workers=1)
        await backend.start()
        try:
            return await _database(backend, Store(tmp_path))
        finally:
            await backend.close()

    db = asyncio.run(asyncio.wait_for(first(), 120))
    store = Store(tmp_path)
    payload = {"request": {"engine": "scripted", "database": db, "steps": 2, "step_s": 0.01}}
    stale = JobInfo(id="stale1", kind=JobKind.synth, status=JobStatus.running, created_at=now(), last_event=2)
    store.put_job(stale, {"kind": "synth", "payload": payload})
    lines = [
        JobEvent(id=1, job="stale1", type=EventType.queued, time=1.0).model_dump_json(),
        JobEvent(id=2, job="stale1", type=EventType.started, time=2.0).model_dump_json(),
    ]
    store.put_events("stale1", lines)

    async def second() -> list[JobEvent]:
        backend = EmbeddedBackend(store, workers=1)
        await backend.start()
        try:
            return await _collect(backend, "stale1")
        finally:
            await backend.close()

    events = asyncio.run(asyncio.wait_for(second(), 60))
    assert [e.id for e in events] == list(range(1, len(events) + 1))
    assert [e.type for e in events][:3] == ["queued", "started", "started"]
    assert events[2].data["attempt"] == 2
    assert events[-1].type == EventType.done
    assert store.job_info("stale1").status == JobStatus.done


def test_a_killed_engine_process_is_replaced_and_its_job_run_again(tmp_path: Path) -> None:
    """SIGKILL of an engine process (as the OOM killer would): the job runs again on a fresh process
    and ends ``done``, later jobs run, and health stays truthful."""
    import signal

    go = tmp_path / "go"  # the job waits for it: still running when killed, however loaded the machine

    async def scenario() -> tuple[list[JobEvent], list[JobEvent], dict[str, Any]]:
        store = Store(tmp_path)
        backend = EmbeddedBackend(store, workers=1)
        await backend.start()
        try:
            db = await _database(backend, store)
            request = {"engine": "scripted", "database": db, "steps": 3, "step_s": 0.05}
            job = await _submit(backend, store, "synth", {"request": request | {"go_file": str(go)}})
            while store.job_info(job).status != JobStatus.running:
                await asyncio.sleep(0.02)
            pid = backend._processes[0].pid
            assert pid is not None
            os.kill(pid, signal.SIGKILL)
            go.touch()  # attempt 2 runs through
            quick = {"request": {"engine": "scripted", "database": db, "steps": 1, "step_s": 0.0}}
            later = await _submit(backend, store, "synth", quick)
            first_events = await _collect(backend, job)
            later_events = await _collect(backend, later)
            return first_events, later_events, await backend.health()
        finally:
            await backend.close()

    first_events, later_events, health = asyncio.run(asyncio.wait_for(scenario(), 120))
    assert first_events[-1].type == EventType.done
    assert [e.data.get("attempt") for e in first_events if e.type == EventType.started] == [1, 2]
    assert [e.id for e in first_events] == list(range(1, len(first_events) + 1))
    # every event carries the run that published it: 0 for queued, then each start's attempt
    starts = [i for i, e in enumerate(first_events) if e.type == EventType.started]
    assert first_events[0].attempt == 0
    assert {e.attempt for e in first_events[starts[0] : starts[1]]} == {1}
    assert {e.attempt for e in first_events[starts[1] :]} == {2}
    assert later_events[-1].type == EventType.done
    assert health["restarts"] == 1 and health["workers_ready"] == 1 and "error" not in health


def test_a_result_shorter_than_asked_says_so(tmp_path: Path) -> None:
    async def scenario() -> list[JobEvent]:
        store = Store(tmp_path)
        backend = EmbeddedBackend(store, workers=1)
        await backend.start()
        try:
            db = await _database(backend, store)
            short = {"request": {"engine": "scripted", "database": db, "steps": 1, "frames": 100}}
            full = {"request": {"engine": "scripted", "database": db, "steps": 1, "frames": 10}}
            a = await _collect(backend, await _submit(backend, store, "synth", short))
            b = await _collect(backend, await _submit(backend, store, "synth", full))
            return [a[-1], b[-1]]
        finally:
            await backend.close()

    short_done, full_done = asyncio.run(asyncio.wait_for(scenario(), 120))
    assert short_done.type == full_done.type == EventType.done
    assert short_done.data["short"] == {"frames": 10, "requested_frames": 100}
    assert "short" not in full_done.data
