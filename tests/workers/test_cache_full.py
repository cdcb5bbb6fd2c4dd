"""Caches are caches: a worker whose cache disk is full evicts and retries, and when it cannot, the
job goes to another worker and the operator is told; the user never reads ``storage_full``.

Before: the download's ``ENOSPC`` (or ``EFBIG``) ended the job ``failed`` with ``storage_full`` and
its advice to free space by deleting clips, though nothing of the user's was full: no eviction, no
other worker tried.
"""

from __future__ import annotations

import asyncio
import errno
from pathlib import Path

import numpy as np
import pytest
import redis

from engines.base import container
from schemas import EventType, JobEvent
from workers.dbcache import CacheFull, DiskCache
from workers.redis_backend import RedisBackend
from workers.store import Store

from .conftest import GUARD_S, add_database, run, spawn_worker, synth, wait_for


def _database(root: Path, name: str, size: int) -> container.Manifest:
    """A database of one ``size``-byte array written under ``root/name`` (the object store's copy)."""
    return container.write_dir(root / name, {"a": np.zeros(size, dtype=np.uint8)})


class SmallDisk:
    """A disk of ``capacity`` bytes holding the cache: a download that would overfill it fails with
    ``ENOSPC``, as the kernel's would (counting the complete files under the cache root)."""

    def __init__(self, cache: DiskCache, source: Path, capacity: int) -> None:
        self.cache, self.source, self.capacity = cache, source, capacity

    def used(self) -> int:
        root = self.cache.root
        return sum(p.stat().st_size for p in root.rglob("*.npy") if p.is_file()) if root.exists() else 0

    def fetcher(self, db_id: str) -> object:
        def fetch(file: str, path: Path) -> None:
            data = (self.source / db_id / file).read_bytes()
            if self.used() + len(data) > self.capacity:
                raise OSError(errno.ENOSPC, "No space left on device")
            path.write_bytes(data)

        return fetch


def test_a_full_cache_disk_evicts_the_oldest_and_retries(tmp_path: Path) -> None:
    source = tmp_path / "store"
    manifests = {name: _database(source, name, 40_000) for name in ("a", "b", "c")}
    cache = DiskCache(tmp_path / "cache", max_bytes=10**9)  # the byte bound is not what stops it
    disk = SmallDisk(cache, source, capacity=100_000)  # room for two databases, not three
    for name in ("a", "b"):
        cache.fetch(name, manifests[name], disk.fetcher(name))  # type: ignore[arg-type]
    assert cache.path_if_cached("a") is not None  # a used last: b is the oldest
    cache.fetch("c", manifests["c"], disk.fetcher("c"))  # type: ignore[arg-type]
    assert [db for _, _, db in cache.entries()] == ["a", "c"]


def test_a_database_that_fits_nowhere_is_cache_full_not_storage_full(tmp_path: Path) -> None:
    from workers.storage_errors import storage_problem

    source = tmp_path / "store"
    manifest = _database(source, "big", 200_000)
    cache = DiskCache(tmp_path / "cache", max_bytes=10**9)
    disk = SmallDisk(cache, source, capacity=100_000)
    with pytest.raises(CacheFull) as full:
        cache.fetch("big", manifest, disk.fetcher("big"))  # type: ignore[arg-type]
    assert "is full" in str(full.value) and "SEGUE_DISK_CACHE_MB" in str(full.value)
    assert not isinstance(full.value, OSError)
    assert storage_problem(full.value.__cause__) is not None  # the disk's own error, kept as the cause
    assert cache.entries() == []


@pytest.mark.slow
def test_a_worker_whose_cache_disk_is_full_gives_the_job_to_another(
    redis_url: str, rclient: redis.Redis, s3_url: str, tmp_path: Path
) -> None:
    """Two workers on their own disks, the store in S3: ``small`` can write no file over 16 KiB
    (its disk is full for the database's arrays), ``roomy`` is busy with another job at first. The
    job goes to ``small``, which gives it back (logged), and ``roomy`` runs it."""
    store = Store(s3_url, tmp_path / "api")
    db = add_database(store)
    go = tmp_path / "go"
    log = tmp_path / "small.log"
    roomy = spawn_worker(redis_url, store, "roomy", data_dir=tmp_path / "roomy")
    small = None
    try:

        async def scenario() -> list[JobEvent]:
            backend = RedisBackend(store, redis_url, block_ms=200)
            await backend.start()
            try:
                busy, payload = synth(store, db, steps=1, step_s=0.0, go_file=str(go))
                await backend.submit(busy, "synth", payload)
                await asyncio.to_thread(
                    wait_for, lambda: store.job_info(busy.id).status.value == "running", GUARD_S, 0.05
                )
                nonlocal small
                small = spawn_worker(
                    redis_url, store, "small", log=log, data_dir=tmp_path / "small", file_size_limit=16 << 10
                )
                info, payload = synth(store, db, steps=2, step_s=0.0)
                await backend.submit(info, "synth", payload)
                await asyncio.to_thread(
                    wait_for,
                    lambda: "goes back to the queue" in log.read_text(),
                    GUARD_S,
                    0.05,
                    "the give-back",
                )
                go.touch()
                return [e async for e in backend.events(info.id)]
            finally:
                await backend.close()

        events = run(asyncio.wait_for(scenario(), 3 * GUARD_S))
    finally:
        for proc in (roomy, small):
            if proc is not None:
                proc.kill()
                proc.wait(timeout=GUARD_S)
    assert events[-1].type == EventType.done
    assert [e.data["worker"] for e in events if e.type == EventType.started][-1] == "roomy"
    assert all((e.data.get("error") or {}).get("code") != "storage_full" for e in events)
    text = log.read_text()
    assert "worker small: the cache disk at" in text and "is full" in text
