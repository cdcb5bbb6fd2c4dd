"""Staged uploads (the bytes of a large clip a worker is to parse) never outlive their parse.

Before: the small job's own ``finally`` removed them, so a parse its supervisor killed (memory or
time limit), a dead-lettered or cancelled one, or an upload the backend refused left them in the
store for good, with no route to delete them and no sweep.
"""

from __future__ import annotations

import asyncio
import gzip
import io
import os
import socket
import time
from dataclasses import replace
from pathlib import Path

import anyio
import numpy as np
import pytest

from motion import BvhLimits, parse_bvh, write_bvh
from motion.samples import sample_path
from schemas import EventType, JobEvent
from service.errors import ApiError
from service.metrics import Metrics
from service.tasks import TaskRunner
from service.uploads import Upload, parse_upload
from tests.motion.retarget.characters import character
from workers.embedded import EmbeddedBackend
from workers.redis_backend import RedisBackend
from workers.store import NotFoundError, Store
from workers.tasks import task_payload

from .conftest import GUARD_S, new_job, run, worker_thread

LIMITS = [1024, 2_000_000, 1 << 28]


def _upload() -> bytes:
    buf = io.StringIO()
    write_bvh(character("mixamo", scale=1.2), buf)
    return gzip.compress(buf.getvalue().encode())


def _long_parse() -> bytes:
    """A walk's frames 100 times over (32k frames x 43 joints): a parse of about a second, which a
    1-MiB memory limit stops at its first check."""
    walk = parse_bvh(sample_path("walk").read_bytes())
    motion = replace(
        walk,
        rotations=np.concatenate([walk.rotations] * 100),
        root_positions=np.concatenate([walk.root_positions] * 100),
    )
    buf = io.StringIO()
    write_bvh(motion, buf)
    return buf.getvalue().encode()


def _staged_gone(store: Store, key: str) -> bool:
    try:
        store.staged_bytes(key)
    except NotFoundError:
        return True
    return False


async def _parse(backend: EmbeddedBackend | RedisBackend, store: Store, key: str) -> list[JobEvent]:
    payload = task_payload("clip", staged=key, name="big.bvh.gz", units=None, limits=LIMITS)
    job = new_job(store, "task", payload)
    await backend.submit(job, "task", payload)
    return [e async for e in backend.events(job.id)]


@pytest.mark.slow
def test_a_parse_killed_by_its_memory_limit_leaves_no_staged_upload_embedded(store: Store) -> None:
    store.put_staged("up1", _long_parse())

    async def scenario() -> list[JobEvent]:
        backend = EmbeddedBackend(store, 1, max_rss_bytes=1 << 20)  # any engine process is over 1 MiB
        await backend.start()
        try:
            return await asyncio.wait_for(_parse(backend, store, "up1"), GUARD_S)
        finally:
            await backend.close()

    log = run(scenario())
    assert log[-1].type == EventType.failed and log[-1].data["error"]["code"] == "memory_limit"
    assert _staged_gone(store, "up1")


@pytest.mark.slow
def test_a_parse_killed_by_its_memory_limit_leaves_no_staged_upload_redis(
    redis_url: str, store: Store
) -> None:
    store.put_staged("up2", _long_parse())

    async def scenario() -> list[JobEvent]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            return await asyncio.wait_for(_parse(backend, store, "up2"), GUARD_S)
        finally:
            await backend.close()

    with worker_thread(redis_url, store, "t1", max_job_memory_mb=1):
        log = run(scenario())
    assert log[-1].type == EventType.failed and log[-1].data["error"]["code"] == "memory_limit"
    assert _staged_gone(store, "up2")


def test_an_upload_the_backend_refuses_leaves_no_staged_upload(
    store: Store, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("service.uploads.INLINE_VALUES", 0)  # every clip is parsed by a worker
    with socket.socket() as s:  # a port nothing listens on: Redis is down
        s.bind(("127.0.0.1", 0))
        down = f"redis://127.0.0.1:{s.getsockname()[1]}/0"

    async def scenario() -> ApiError:
        backend = RedisBackend(store, down)
        await backend.start()
        try:
            with pytest.raises(ApiError) as refused:
                await parse_upload(
                    Upload.from_bytes("big.bvh.gz", _upload()),
                    None,
                    BvhLimits(*LIMITS),
                    store,
                    backend,
                    Metrics(),
                    TaskRunner(),
                    anyio.CapacityLimiter(1),
                )
            return refused.value
        finally:
            await backend.close()

    refused = run(scenario())
    assert refused.status == 503
    assert store.objects.children("staged") == []


def _age(store: Store, key: str, seconds: float) -> None:
    path = store.objects.local_path(f"staged/{key}")
    assert path is not None
    when = time.time() - seconds
    os.utime(path, (when, when))


def test_the_sweep_removes_staged_uploads_older_than_its_age(store: Store) -> None:
    old, fresh = store.stage(b"old bytes"), store.stage(b"fresh bytes")
    store.put_staged("legacy", b"an earlier version's key")
    _age(store, old, 7200)
    _age(store, "legacy", 7200)
    assert sorted(store.sweep_staged(3600)) == sorted([old, "legacy"])
    assert store.staged_keys() == [fresh]
    assert store.staged_bytes(fresh) == b"fresh bytes"


def test_the_sweep_on_an_object_store(s3_url: str, tmp_path: Path) -> None:
    store = Store(s3_url, tmp_path / "cache")
    key = store.stage(b"bytes")
    assert store.sweep_staged(3600) == []  # written just now
    assert store.sweep_staged(3600, now_s=time.time() + 7200) == [key]
    assert store.staged_keys() == []
