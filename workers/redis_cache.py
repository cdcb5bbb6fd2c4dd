"""Databases cached in Redis as the bytes of their ``data.npz`` (never pickle), chunked.

The store's ``databases/<id>/data.npz`` is the durable copy; Redis only saves workers on other
machines the disk read (and may be a separate ``allkeys-lru`` instance). Keys (see
:mod:`workers.redis_keys`): ``segue:db:<id>:n`` holds the chunk count and ``segue:db:<id>:<i>`` the
chunks (``chunk_size`` bytes each, the last one shorter).

Writing is one ``WATCH``/``MULTI`` transaction: the chunks, then the count with ``SET NX EX``. The
count key is the commit point, so a reader never sees a mix of two writes; if it is already there (or
appears while we write) nothing is written. Reading takes the count, then the chunks; a missing chunk
(evicted) or a wrong total size drops the count so the next load repopulates from disk. Any Redis
error falls back to the disk copy: a flushed or unreachable cache only costs a disk read.
"""

from __future__ import annotations

import logging
from typing import cast

import redis

from .redis_keys import CHUNK_SIZE, RedisKeys
from .store import Store

log = logging.getLogger("segue.redis.cache")

CACHE_TTL_S = 7 * 24 * 3600


class DatabaseCache:
    """Chunked database bytes in Redis over the store's files (a bytes client: no response decoding)."""

    def __init__(
        self,
        client: redis.Redis,
        store: Store,
        keys: RedisKeys,
        chunk_size: int = CHUNK_SIZE,
        ttl_s: int = CACHE_TTL_S,
        batch: int = 16,
    ) -> None:
        if chunk_size <= 0:
            raise ValueError("chunk_size must be positive")
        self.client, self.store, self.keys = client, store, keys
        self.chunk_size, self.ttl_s, self.batch = chunk_size, ttl_s, max(1, batch)

    def get(self, db_id: str) -> bytes | None:
        """The cached bytes, or None (not cached, partly evicted)."""
        raw = cast(bytes | None, self.client.get(self.keys.db_count(db_id)))
        if raw is None:
            return None
        count = int(raw)
        chunks: list[bytes | None] = []
        for start in range(0, count, self.batch):
            names = [self.keys.db_chunk(db_id, i) for i in range(start, min(start + self.batch, count))]
            chunks.extend(cast(list[bytes | None], self.client.mget(names)))
        if any(c is None for c in chunks) or any(len(c or b"") != self.chunk_size for c in chunks[:-1]):
            log.info("database %s: cache incomplete, dropping it", db_id)
            self.client.delete(self.keys.db_count(db_id))
            return None
        return b"".join(c for c in chunks if c is not None)

    def put(self, db_id: str, data: bytes) -> bool:
        """Cache ``data`` unless it is cached already; True when this call wrote it."""
        count_key = self.keys.db_count(db_id)
        count = max(1, -(-len(data) // self.chunk_size))
        with self.client.pipeline() as pipe:
            try:
                pipe.watch(count_key)  # type: ignore[no-untyped-call]
                if pipe.exists(count_key):
                    return False
                pipe.multi()
                for i in range(count):
                    chunk = data[i * self.chunk_size : (i + 1) * self.chunk_size]
                    pipe.set(self.keys.db_chunk(db_id, i), chunk, ex=self.ttl_s)
                pipe.set(count_key, count, nx=True, ex=self.ttl_s)
                result = pipe.execute()
            except redis.WatchError:
                return False
        return bool(result[-1])

    def load(self, db_id: str) -> bytes:
        """The database bytes: from Redis, else from disk (then cached). Raises ``NotFoundError``."""
        try:
            data = self.get(db_id)
        except redis.RedisError as exc:
            log.warning("database cache unavailable (%s); reading %s from disk", exc, db_id)
            return self.store.database_arrays_bytes(db_id)
        if data is not None:
            return data
        data = self.store.database_arrays_bytes(db_id)
        self.save(db_id, data)
        return data

    def save(self, db_id: str, data: bytes) -> None:
        """Cache freshly built (or just read) bytes; a cache failure is only logged."""
        try:
            self.put(db_id, data)
        except redis.RedisError as exc:
            log.warning("could not cache database %s: %s", db_id, exc)
