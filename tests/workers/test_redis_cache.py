"""The database cache: chunked npz bytes in Redis over the store's durable copy.

Chunking, eviction and outage handling are unit-tested on fakeredis (a real server adds nothing
there); surviving FLUSHALL is tested end to end with workers on the real server.
"""

from __future__ import annotations

import asyncio

import fakeredis
import numpy as np
import pytest
import redis

from schemas import EventType, JobEvent
from workers.redis_backend import RedisBackend
from workers.redis_cache import DatabaseCache
from workers.redis_keys import RedisKeys
from workers.store import NotFoundError, Store, load_npz

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


def test_chunked_round_trip_and_set_nx(fake: tuple[fakeredis.FakeServer, redis.Redis], store: Store) -> None:
    _, client = fake
    cache = DatabaseCache(client, store, KEYS, chunk_size=1000, ttl_s=60)
    data = np.random.default_rng(0).bytes(5500)
    assert cache.get("db1") is None
    assert cache.put("db1", data) is True
    assert client.get(KEYS.db_count("db1")) == b"6"
    assert [len(client.get(KEYS.db_chunk("db1", i)) or b"") for i in range(6)] == [1000] * 5 + [500]
    assert 0 < client.ttl(KEYS.db_chunk("db1", 0)) <= 60
    assert cache.get("db1") == data
    assert cache.put("db1", b"other bytes") is False  # already cached: not overwritten
    assert cache.get("db1") == data
    assert cache.put("empty", b"") is True and cache.get("empty") == b""


def test_eviction_and_outage_fall_back_to_disk(
    fake: tuple[fakeredis.FakeServer, redis.Redis], store: Store
) -> None:
    server, client = fake
    db = add_database(store)
    disk = store.database_arrays_bytes(db)
    cache = DatabaseCache(client, store, KEYS, chunk_size=max(1, len(disk) // 3))
    assert cache.load(db) == disk  # miss: read from disk, then cached
    count = int(client.get(KEYS.db_count(db)) or 0)
    assert count >= 3
    client.delete(KEYS.db_chunk(db, 1))  # evicted by allkeys-lru
    assert cache.get(db) is None and not client.exists(KEYS.db_count(db))  # incomplete: dropped
    assert cache.load(db) == disk and cache.get(db) == disk  # repopulated
    server.connected = False  # the cache Redis is down: the disk copy serves
    assert cache.load(db) == disk
    cache.save(db, disk)  # only logged
    with pytest.raises(NotFoundError):
        cache.load("nosuchdb")


def test_database_cache_survives_flushall(redis_url: str, rclient: redis.Redis, store: Store) -> None:
    db = add_database(store, build=False)
    chunk = 32 << 10
    bytes_client = redis.Redis.from_url(redis_url)

    async def run_job(kind: str, payload: dict[str, object]) -> list[JobEvent]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        try:
            job = new_job(store, kind, payload)
            await backend.submit(job, kind, payload)
            return await asyncio.wait_for(_all(backend, job.id), GUARD_S)
        finally:
            await backend.close()

    def cached() -> bytes:
        n = int(bytes_client.get(KEYS.db_count(db)) or 0)
        return b"".join(bytes_client.get(KEYS.db_chunk(db, i)) or b"" for i in range(n))

    with worker_thread(redis_url, store, "t1", cache_chunk_bytes=chunk):
        built = run(run_job("build", {"database": db}))
    disk = store.database_arrays_bytes(db)
    assert built[-1].type == EventType.done and len(disk) > 2 * chunk
    assert int(bytes_client.get(KEYS.db_count(db)) or 0) == -(-len(disk) // chunk)
    assert cached() == disk  # populated by the build
    assert sorted(load_npz(cached())) == sorted(load_npz(disk))

    rclient.flushall()  # Redis loses the cache (and the queue): the database is rebuilt from disk
    request = {"engine": "clip", "database": db, "clip": "walk", "start": 0, "end": 20}
    # a fresh worker: empty in-memory LRU
    with worker_thread(redis_url, store, "t2", cache_chunk_bytes=chunk):
        events = run(run_job("synth", {"request": request}))
    assert events[-1].type == EventType.done
    assert store.result_motion(events[-1].job, events[-1].data["result"]).num_frames == 20
    assert cached() == disk
    bytes_client.close()


async def _all(backend: RedisBackend, job_id: str) -> list[JobEvent]:
    return [e async for e in backend.events(job_id)]
