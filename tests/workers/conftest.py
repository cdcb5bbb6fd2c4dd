"""Fixtures for the runtime tests: a real ``redis-server`` on a free port, stores, databases, workers.

The server is started once per session (``--save "" --appendonly no``, bound to 127.0.0.1) and
flushed around every test that uses ``redis_url``. Without the binary the Redis tests are skipped
with the reason; under CI (``CI=true``) a missing binary is an error, since ``.ci/run`` installs it.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import resource
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable, Coroutine, Iterator
from pathlib import Path
from typing import Any, TypeVar

import pytest
import redis

import tests.workers.scripted_engine  # noqa: F401  (registers the scripted engine in this process)
from engines.registry import parse_database_spec
from motion.samples import sample_path
from schemas import DatabaseInfo, DatabaseStatus, EventType, JobInfo, JobStatus
from schemas.databases import database_id
from schemas.jobs import JobKind
from tests.s3server import stop_server
from workers.execute import EngineCache, execute_job
from workers.redis_worker import run_worker
from workers.settings import Settings
from workers.store import Store, now

REPO = Path(__file__).resolve().parents[2]
PLUGINS = "tests.workers.scripted_engine"
T = TypeVar("T")
GUARD_S = 120.0
"""How long a test waits for something that should happen before it calls it a hang: generous, so
that a loaded machine is never mistaken for a broken one (tests assert results, not speed)."""


def run(coro: Coroutine[Any, Any, T]) -> T:
    """Run a coroutine to completion (the suite has no asyncio plugin)."""
    return asyncio.run(coro)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="session")
def redis_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """URL of a private redis-server (never the one on 6379)."""
    binary = shutil.which("redis-server")
    if binary is None:
        reason = (
            "redis-server is not installed (apt-get install redis-server); the Redis backend tests need it"
        )
        if os.environ.get("CI") == "true":
            pytest.fail(reason)
        pytest.skip(reason)
    workdir = tmp_path_factory.mktemp("redis")
    for _attempt in range(3):
        port = _free_port()
        proc = subprocess.Popen(
            [
                binary,
                "--port",
                str(port),
                "--bind",
                "127.0.0.1",
                "--save",
                "",
                "--appendonly",
                "no",
                "--dir",
                str(workdir),
                "--loglevel",
                "warning",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        url = f"redis://127.0.0.1:{port}/0"
        client = redis.Redis.from_url(url)
        deadline = time.monotonic() + GUARD_S
        while proc.poll() is None and time.monotonic() < deadline:
            try:
                client.ping()
                break
            except redis.ConnectionError:
                time.sleep(0.02)
        else:
            proc.kill()
            proc.wait()
            continue  # the port was taken meanwhile, or the server did not start: try another
        client.close()
        try:
            yield url
        finally:
            stop_server(proc)
        return
    pytest.fail("could not start redis-server")


@pytest.fixture
def redis_url(redis_server: str) -> Iterator[str]:
    """The test server, flushed before and after the test."""
    client = redis.Redis.from_url(redis_server)
    client.flushall()
    try:
        yield redis_server
    finally:
        client.flushall()
        client.close()


@pytest.fixture
def rclient(redis_url: str) -> Iterator[redis.Redis]:
    client = redis.Redis.from_url(redis_url, decode_responses=True)
    yield client
    client.close()


@pytest.fixture
def store(tmp_path: Path) -> Store:
    return Store(tmp_path / "data")


@pytest.fixture
def s3_store(s3_url: str, tmp_path: Path) -> Store:
    """A store on the S3 server, with this process's cache under ``tmp_path/api``."""
    return Store(s3_url, tmp_path / "api")


def add_database(store: Store, build: bool = True, fps: float = 30.0) -> str:
    """A clips database of the bundled walk sample (built in-process unless ``build`` is False)."""
    clip = store.put_clip("walk.bvh.gz", sample_path("walk").read_bytes())
    spec = parse_database_spec({"kind": "clips", "clips": [{"clip": clip.id, "name": "walk"}], "fps": fps})
    db_id = database_id(spec, [clip.id])
    info = DatabaseInfo(
        id=db_id, kind="clips", status=DatabaseStatus.queued, clips=["walk"], created_at=now()
    )
    store.put_database_info(info, spec.model_dump(mode="json"))
    if build:
        events: list[EventType] = []
        execute_job(
            store,
            "build0",
            "build",
            {"database": db_id},
            lambda t, d: events.append(t),
            lambda: False,
            EngineCache(),
        )
        if events[-1] != EventType.done:
            raise RuntimeError(f"test database build failed: {events}")
    return db_id


def new_job(store: Store, kind: str, payload: dict[str, Any]) -> JobInfo:
    """A job stored on disk (status queued), as the API stores it before submitting."""
    request = payload.get("request", {})
    info = JobInfo(
        id=uuid.uuid4().hex,
        kind=JobKind(kind),
        engine=request.get("engine"),
        database=request.get("database") or payload.get("database"),
        status=JobStatus.queued,
        created_at=now(),
    )
    store.put_job(info, {"kind": kind, "payload": payload})
    return info


def synth(store: Store, db_id: str, **request: Any) -> tuple[JobInfo, dict[str, Any]]:
    payload = {"request": {"engine": "scripted", "database": db_id, **request}}
    return new_job(store, "synth", payload), payload


@contextlib.contextmanager
def worker_thread(redis_url: str, store: Store, name: str, **fields: Any) -> Iterator[threading.Event]:
    """A worker running in a thread of this process (``fields`` of its
    :class:`~workers.settings.Settings`); stopped (and joined) on exit.

    Its heartbeat lives 60 s: a thread worker is never killed (it deletes its key when it stops), and
    with a 1-s TTL a stall of this process (a loaded machine) made a second worker thread take the
    first one's job as if it had died (tests/workers/test_recovery.py, test_redis_backend.py)."""
    stop = threading.Event()
    fields = {"heartbeat_s": 0.2, "heartbeat_ttl_s": 60.0, "block_ms": 100, **fields}
    fields = {"store_url": store.url, "data_dir": store.root, **fields}
    settings = Settings(redis_url=redis_url, worker_name=name, **fields)
    thread = threading.Thread(target=run_worker, args=(settings, stop), daemon=True)
    thread.start()
    try:
        yield stop
    finally:
        stop.set()
        thread.join(timeout=GUARD_S)
        if thread.is_alive():
            raise RuntimeError(f"worker thread {name} did not stop")


def spawn_worker(
    redis_url: str,
    store: Store,
    name: str,
    log: Path | None = None,
    data_dir: Path | None = None,
    file_size_limit: int | None = None,
    **settings: str,
) -> subprocess.Popen[bytes]:
    """A ``segue worker`` process (heartbeat 0.2 s, TTL 5 s, 100-ms blocking reads; ``settings``:
    more :class:`workers.settings.Settings` fields as their ``SEGUE_*`` variables, e.g.
    ``heartbeat_ttl_s="600"``; its stderr appended to ``log`` when given; ``data_dir``: its own
    local directory, default the store's; ``file_size_limit``: the largest file it and its engine
    process may write, bytes (``RLIMIT_FSIZE``: beyond it a write fails with ``EFBIG``, as on a
    full disk)). The TTL bounds how soon a
    killed worker's job is taken over; with 1 s, a live worker that a loaded machine left unscheduled
    for 0.8 s had its job taken by another as if it had died."""
    own = {"heartbeat_s": "0.2", "heartbeat_ttl_s": "5.0", "block_ms": "100", "log_level": "WARNING"}
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
        SEGUE_ENGINE_PLUGINS=PLUGINS,
        SEGUE_STORE_URL=store.url,
    )
    env.update({f"SEGUE_{key.upper()}": value for key, value in {**own, **settings}.items()})
    data = str(data_dir or store.root)
    cmd = [
        sys.executable,
        "-m",
        "service.cli",
        "worker",
        "--redis",
        redis_url,
        "--data",
        data,
        "--name",
        name,
    ]

    def limit() -> None:
        if file_size_limit is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (file_size_limit, file_size_limit))

    if log is None:
        return subprocess.Popen(cmd, env=env, cwd=REPO, preexec_fn=limit)
    with log.open("ab") as sink:
        return subprocess.Popen(cmd, env=env, cwd=REPO, stderr=sink, preexec_fn=limit)


@contextlib.contextmanager
def worker_processes(
    redis_url: str, store: Store, names: list[str], **settings: str
) -> Iterator[dict[str, subprocess.Popen[bytes]]]:
    """``spawn_worker`` for each name (``settings``: more worker settings, e.g.
    ``heartbeat_ttl_s="600"``); killed (SIGKILL) on exit if still running."""
    procs = {name: spawn_worker(redis_url, store, name, **settings) for name in names}
    try:
        yield procs
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=GUARD_S)


def wait_for(
    condition: Callable[[], Any], timeout: float = GUARD_S, interval: float = 0.02, what: str = ""
) -> Any:
    """Poll until ``condition()`` is truthy; returns its value (fails the test on timeout: a guard
    against a hang, never a speed bar)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(interval)
    pytest.fail(f"timed out after {timeout} s waiting for {what or condition}")
