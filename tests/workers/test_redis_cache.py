"""The database cache: chunked store objects in Redis between the object store and workers' disks.

Chunking, eviction and outage handling are unit-tested on fakeredis (a real server adds nothing
there); surviving FLUSHALL is tested end to end with workers on the real server.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import fakeredis
import numpy as np
import pytest
import redis

from schemas import EventType, JobEvent
from workers.redis_backend import RedisBackend
from workers.redis_cache import DatabaseCache
from workers.redis_keys import RedisKeys
from workers.store import Store

from .conftest import GUARD_S, add_database, new_job, run, worker_thread

KEYS = RedisKeys()


def test_keys_default_and_custom_prefix() -> None:
    assert (KEYS.jobs, KEYS.group, KEYS.dead) == ("segue:jobs", "segue-workers", "segue:jobs:dead")
    assert KEYS.events("j") == "segue:events:j" and KEYS.event_seq("j") == "segue:events:j:seq"
    assert (KEYS.job("j"), KEYS.terminal("j"), KEYS.cancel("j")) == (
        "segue:job:j",
        "segue:job:j:terminal",
        "segue:cancel:j",
    )
    assert (KEYS.worker("w"), KEYS.db_count("d"), KEYS.db_chunk("d", 3), KEYS.build_lock("d")) == (
        "segue:worker:w",
        "segue:db:d:n",
        "segue:db:d:3",
        "segue:lock:build:d",
    )
    other = RedisKeys("t1:")
    assert other.jobs == "t1:jobs" and other.worker_pattern == "t1:worker:*"


@pytest.fixture
def fake() -> tuple[fakeredis.FakeServer, redis.Redis]:
    server = fakeredis.FakeServer()
    return server, fakeredis.FakeRedis(server=server)


def test_chunked_round_trip_and_set_nx(fake: tuple[fakeredis.FakeServer, redis.Redis]) -> None:
    _, client = fake
    cache = DatabaseCache(client, KEYS, chunk_size=1000, ttl_s=60)
    data = np.random.default_rng(0).bytes(5500)
    key = "databases/db1/arrays/x.npy"
    assert cache.get(key) is None
    assert cache.write(key, data) is True
    assert client.get(KEYS.db_count(key)) == b"6"
    assert [len(client.get(KEYS.db_chunk(key, i)) or b"") for i in range(6)] == [1000] * 5 + [500]
    assert 0 < client.ttl(KEYS.db_chunk(key, 0)) <= 60
    assert cache.get(key) == data
    assert cache.write(key, b"other bytes") is False  # already cached: not overwritten
    assert cache.get(key) == data
    assert cache.write("empty", b"") is True and cache.get("empty") == b""


def test_eviction_and_outage_are_misses(fake: tuple[fakeredis.FakeServer, redis.Redis]) -> None:
    server, client = fake
    cache = DatabaseCache(client, KEYS, chunk_size=100, max_object_bytes=1000)
    assert cache.wants(1000) and not cache.wants(1001)
    data = bytes(range(250))
    cache.put("k", data)
    client.delete(KEYS.db_chunk("k", 1))  # evicted by allkeys-lru
    assert cache.get("k") is None and not client.exists(KEYS.db_count("k"))  # incomplete: dropped
    cache.put("k", data)
    assert cache.get("k") == data  # repopulated
    server.connected = False  # the cache Redis is down: a miss, only logged
    assert cache.get("k") is None
    cache.put("k", data)
    with pytest.raises(redis.ConnectionError):
        cache.read("k")


def test_workers_share_downloads_through_redis(
    redis_url: str, rclient: redis.Redis, s3_url: str, tmp_path: Path
) -> None:
    """With an object store, a worker fetches each database object through Redis: the first
    download fills it, a fresh worker with an empty disk reads it from there, and a FLUSHALL
    only costs a download from the object store."""
    api = Store(s3_url, tmp_path / "api")
    db = add_database(api, build=False)
    chunk = 32 << 10
    bytes_client = redis.Redis.from_url(redis_url)

    async def run_job(kind: str, payload: dict[str, object]) -> list[JobEvent]:
        backend = RedisBackend(api, redis_url)
        await backend.start()
        try:
            job = new_job(api, kind, payload)
            await backend.submit(job, kind, payload)
            return await asyncio.wait_for(_all(backend, job.id), GUARD_S)
        finally:
            await backend.close()

    def cached_keys() -> set[str]:
        return {k.decode().removesuffix(":n") for k in bytes_client.scan_iter(KEYS.db_count("*"))}

    request = {"engine": "clip", "database": db, "clip": "walk", "start": 0, "end": 20}
    with worker_thread(redis_url, api, "t1", data_dir=tmp_path / "w1", cache_chunk_bytes=chunk):
        built = run(run_job("build", {"database": db}))
        assert built[-1].type == EventType.done
        first = run(run_job("synth", {"request": request}))
    assert first[-1].type == EventType.done
    manifest = api.database_manifest(db)
    objects = {f"databases/{db}/arrays/{f}" for f in manifest.files.values()}
    assert {KEYS.db_count(k).removesuffix(":n") for k in objects} <= cached_keys()
    assert not (tmp_path / "api" / "cache").exists()  # the API process downloaded nothing
    assert (tmp_path / "w1" / "cache" / "databases" / db / "arrays.json").is_file()

    rclient.flushall()  # the cache (and the queue) lost: the object store serves
    with worker_thread(redis_url, api, "t2", data_dir=tmp_path / "w2", cache_chunk_bytes=chunk):
        events = run(run_job("synth", {"request": request}))
    assert events[-1].type == EventType.done
    assert api.result_motion(events[-1].job, events[-1].data["result"]).num_frames == 20
    assert {KEYS.db_count(k).removesuffix(":n") for k in objects} <= cached_keys()
    bytes_client.close()


async def _all(backend: RedisBackend, job_id: str) -> list[JobEvent]:
    return [e async for e in backend.events(job_id)]
