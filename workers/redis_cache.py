"""Database objects cached in Redis (raw ``.npy`` bytes, never pickle), chunked: the second level of
a worker's database cache.

The store is the source of truth (:mod:`workers.store`); each worker keeps the databases it uses on
its own disk, memory-mapped (:class:`workers.dbcache.DiskCache`). This cache sits between the two
for an object store: when a worker downloads a database object of at most ``max_object_bytes``, it
looks here first and, on a miss, puts what it fetched here. So a database is read from the object
store once per cluster rather than once per worker: a new or restarted worker, or one whose disk
cache evicted it, fills its disk from Redis (a LAN round trip, no per-request cost of the object
store). Large arrays (a 100k-frame graph's tables) skip Redis: they would crowd out everything else
in an ``allkeys-lru`` instance, and the object store streams them as fast. With a local store there
is nothing to download and this cache is not used.

Keys (see :mod:`workers.redis_keys`): ``segue:db:<object key>:n`` holds the chunk count and
``segue:db:<object key>:<i>`` the chunks (``chunk_size`` bytes each, the last one shorter).

Writing is one ``WATCH``/``MULTI`` transaction: the chunks, then the count with ``SET NX EX``. The
count key is the commit point, so a reader never sees a mix of two writes; if it is already there (or
appears while we write) nothing is written. Reading takes the count, then the chunks; a missing chunk
(evicted) or a wrong size drops the count so the next download repopulates it. Any Redis error is
logged and counts as a miss: a flushed or unreachable cache only costs a read of the object store.
"""

from __future__ import annotations

import logging
from typing import cast

import redis

from .redis_keys import CHUNK_SIZE, RedisKeys

log = logging.getLogger("segue.redis.cache")

CACHE_TTL_S = 7 * 24 * 3600
DEFAULT_MAX_OBJECT_BYTES = 64 << 20


class DatabaseCache:
    """Chunked store objects in Redis (a bytes client: no response decoding); an
    :class:`~workers.dbcache.ObjectCache`."""

    def __init__(
        self,
        client: redis.Redis,
        keys: RedisKeys,
        chunk_size: int = CHUNK_SIZE,
        ttl_s: int = CACHE_TTL_S,
        batch: int = 16,
        max_object_bytes: int = DEFAULT_MAX_OBJECT_BYTES,
    ) -> None:
        if chunk_size <= 0:
            raise ValueError("chunk_size must be positive")
        self.client, self.keys = client, keys
        self.chunk_size, self.ttl_s, self.batch = chunk_size, ttl_s, max(1, batch)
        self.max_object_bytes = max_object_bytes

    def wants(self, size: int) -> bool:
        """Objects up to ``max_object_bytes`` are cached."""
        return 0 <= size <= self.max_object_bytes

    def read(self, key: str) -> bytes | None:
        """The cached bytes, or None (not cached, partly evicted); Redis errors propagate."""
        raw = cast(bytes | None, self.client.get(self.keys.db_count(key)))
        if raw is None:
            return None
        count = int(raw)
        chunks: list[bytes | None] = []
        for start in range(0, count, self.batch):
            names = [self.keys.db_chunk(key, i) for i in range(start, min(start + self.batch, count))]
            chunks.extend(cast(list[bytes | None], self.client.mget(names)))
        if any(c is None for c in chunks) or any(len(c or b"") != self.chunk_size for c in chunks[:-1]):
            log.info("object %s: cache incomplete, dropping it", key)
            self.client.delete(self.keys.db_count(key))
            return None
        return b"".join(c for c in chunks if c is not None)

    def write(self, key: str, data: bytes) -> bool:
        """Cache ``data`` unless it is cached already; True when this call wrote it (Redis errors
        propagate)."""
        count_key = self.keys.db_count(key)
        count = max(1, -(-len(data) // self.chunk_size))
        with self.client.pipeline() as pipe:
            try:
                pipe.watch(count_key)  # type: ignore[no-untyped-call]
                if pipe.exists(count_key):
                    return False
                pipe.multi()
                for i in range(count):
                    chunk = data[i * self.chunk_size : (i + 1) * self.chunk_size]
                    pipe.set(self.keys.db_chunk(key, i), chunk, ex=self.ttl_s)
                pipe.set(count_key, count, nx=True, ex=self.ttl_s)
                result = pipe.execute()
            except redis.WatchError:
                return False
        return bool(result[-1])

    def get(self, key: str) -> bytes | None:
        """The cached bytes, or None (a miss, or Redis unavailable: logged)."""
        try:
            return self.read(key)
        except redis.RedisError as exc:
            log.warning("database cache unavailable (%s); reading %s from the store", exc, key)
            return None

    def put(self, key: str, data: bytes) -> None:
        """Cache fetched bytes; a cache failure is only logged."""
        try:
            self.write(key, data)
        except redis.RedisError as exc:
            log.warning("could not cache %s: %s", key, exc)
