"""Engine processes die with their worker, and a build's record ends with the runtime's reason.

Before: a ``segue worker`` SIGKILLed during a build left its engine process running until its
parent poll noticed (up to 0.5 s); the build's next progress event hit the closed pipe and the
build's catch-all wrote the database record ``failed`` (``[Errno 32] Broken pipe``) while the job
was still going to be re-run; after three kills that write, not the dead-letter reason, was the
record's final error.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import redis

from engines.registry import parse_database_spec
from motion.samples import sample_path
from schemas import DatabaseInfo, DatabaseStatus, EventType, JobEvent, JobInfo
from schemas.databases import database_id
from tests.processes import engine_children
from workers.redis_backend import RedisBackend
from workers.redis_keys import RedisKeys
from workers.store import Store, now

from .conftest import GUARD_S, REPO, add_database, new_job, run, spawn_worker, wait_for

pytestmark = pytest.mark.slow

KEYS = RedisKeys()


def gone(pid: int) -> bool:
    try:
        return "Z" in Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[:1]
    except OSError:
        return True


def held_database(store: Store, go: Path) -> tuple[str, JobInfo]:
    """A queued ``held`` database (its build reports progress every 10 ms until ``go`` exists) and
    its build job."""
    clip = store.put_clip("walk.bvh.gz", sample_path("walk").read_bytes())
    spec = parse_database_spec(
        {"kind": "held", "clips": [{"clip": clip.id, "name": "walk"}], "go_file": str(go)}
    )
    db_id = database_id(spec, [clip.id])
    job = new_job(store, "build", {"database": db_id})
    info = DatabaseInfo(
        id=db_id,
        kind="held",
        status=DatabaseStatus.queued,
        clips=["walk"],
        created_at=now(),
        build_job=job.id,
    )
    store.put_database_info(info, spec.model_dump(mode="json"))
    return db_id, store.job_info(job.id)


def events(client: redis.Redis, job_id: str) -> list[JobEvent]:
    return [JobEvent.model_validate_json(f["event"]) for _, f in client.xrange(KEYS.events(job_id))]


def building_on(client: redis.Redis, job_id: str, worker: str) -> bool:
    """``worker`` runs the build and its engine has reported progress since that run started."""
    raw = client.get(KEYS.worker(worker))
    if not raw or f'"job": "{job_id}"' not in raw:
        return False
    log = events(client, job_id)
    starts = [i for i, e in enumerate(log) if e.type == EventType.started]
    return bool(starts) and any(e.type == EventType.progress for e in log[starts[-1] :])


def kill_mid_build(client: redis.Redis, proc: subprocess.Popen[bytes], name: str, job_id: str) -> None:
    """SIGKILL a worker once it builds, and wait until its engine process is gone too."""
    wait_for(lambda: building_on(client, job_id, name), what=f"{name} to build")
    children = engine_children(proc.pid)
    assert children, "the worker has an engine process"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=GUARD_S)
    wait_for(lambda: all(gone(c) for c in children), what="the killed worker's engine process to end")


def test_a_killed_worker_leaves_no_failed_record_and_the_rerun_builds(
    redis_url: str, rclient: redis.Redis, store: Store, tmp_path: Path
) -> None:
    go = tmp_path / "go"
    db_id, job = held_database(store, go)

    async def scenario() -> list[JobEvent]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            await backend.submit(job, "build", {"database": db_id})
            w1 = spawn_worker(redis_url, store, "w1", heartbeat_ttl_s="2")
            try:
                await asyncio.to_thread(kill_mid_build, rclient, w1, "w1", job.id)
            finally:
                if w1.poll() is None:
                    w1.kill()
            # the orphan is gone and the job waits for its next run: the record is untouched
            record = store.database_info(db_id)
            assert (record.status, record.error) == (DatabaseStatus.building, None)
            w2 = spawn_worker(redis_url, store, "w2", heartbeat_ttl_s="2")
            try:
                await asyncio.to_thread(wait_for, lambda: building_on(rclient, job.id, "w2"))
                go.touch()
                return await asyncio.wait_for(_all(backend, job.id), GUARD_S)
            finally:
                w2.kill()
                w2.wait(timeout=GUARD_S)
        finally:
            await backend.close()

    log = run(scenario())
    assert log[-1].type == EventType.done
    assert [e.data.get("attempt") for e in log if e.type == EventType.started] == [1, 2]
    assert store.database_info(db_id).status == DatabaseStatus.ready


def test_a_build_dead_lettered_after_three_kills_keeps_the_dead_letter_reason(
    redis_url: str, rclient: redis.Redis, store: Store, tmp_path: Path
) -> None:
    db_id, job = held_database(store, tmp_path / "never")

    async def scenario() -> list[JobEvent]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            await backend.submit(job, "build", {"database": db_id})
            for k in range(3):  # max_deliveries: 3 runs, each killed mid-build
                name = f"w{k}"
                proc = spawn_worker(redis_url, store, name, heartbeat_ttl_s="2")
                try:
                    await asyncio.to_thread(kill_mid_build, rclient, proc, name, job.id)
                finally:
                    if proc.poll() is None:
                        proc.kill()
                assert store.database_info(db_id).status != DatabaseStatus.failed
            last = spawn_worker(redis_url, store, "w3", heartbeat_ttl_s="2")
            try:
                return await asyncio.wait_for(_all(backend, job.id), GUARD_S)
            finally:
                last.send_signal(signal.SIGTERM)  # it ends what it does (the record) first
                last.wait(timeout=GUARD_S)
        finally:
            await backend.close()

    log = run(scenario())
    end = log[-1]
    assert end.type == EventType.failed and end.data["error"]["code"] == "dead_letter"
    record = store.database_info(db_id)
    assert record.status == DatabaseStatus.failed
    assert record.error == end.data["error"]["message"]
    assert "delivered 4 times" in str(record.error)


async def _all(backend: RedisBackend, job_id: str) -> list[JobEvent]:
    return [e async for e in backend.events(job_id)]


OWNER = textwrap.dedent(
    """
    import json, sys, threading, time
    from workers.supervisor import ChildConfig, EngineProcess, Task
    started = threading.Event()
    config = ChildConfig(store_root=sys.argv[1], plugins=["tests.workers.scripted_engine"])
    process = EngineProcess("t", config, lambda *a: started.set(), lambda *a: None)
    process.start()
    process.ready.wait(120)
    process.run(Task("job1", "synth", json.loads(sys.argv[2])))
    started.wait(120)  # the engine process runs the job (busy: it reads no pipe)
    print(process.pid, flush=True)
    time.sleep(600)
    """
)

REAPER = textwrap.dedent(
    """
    import ctypes, os, signal, subprocess, sys
    ctypes.CDLL(None).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER: orphans below come to us
    owner = subprocess.Popen([sys.executable, "-c", *sys.argv[1:]], stdout=subprocess.PIPE)
    child = int(owner.stdout.readline())
    os.kill(owner.pid, signal.SIGKILL)
    owner.wait()
    _, status = os.waitpid(child, 0)  # the engine process, re-parented to this one
    print(os.WTERMSIG(status) if os.WIFSIGNALED(status) else -os.WEXITSTATUS(status))
    """
)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl is Linux's")
def test_a_busy_engine_process_is_killed_with_its_owner(store: Store) -> None:
    """The engine process of a SIGKILLed owner, busy in a job (an engine holding the GIL, reading
    no pipe), is killed by its parent-death handler (SIGKILL) instead of running on until its
    half-second parent poll ends it its own way (before: exit status 0)."""
    db = add_database(store)
    payload = {"request": {"engine": "scripted", "database": db, "spin_s": 60, "budget_s": 120}}
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run(
        [sys.executable, "-c", REAPER, OWNER, store.url, json.dumps(payload)],
        env=env,
        capture_output=True,
        timeout=GUARD_S,
        check=True,
        cwd=REPO,
    )
    assert int(done.stdout.split()[-1]) == signal.SIGKILL
