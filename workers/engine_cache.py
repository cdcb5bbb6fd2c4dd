"""Loaded engines kept per process, bounded by the bytes of their databases.

An engine is loaded from its database's arrays (:meth:`workers.store.Store.database_arrays`: large
arrays memory-mapped, so a load costs what the engine derives from them, not a read of the file).
The cache keeps the most recently used engines while the sum of their databases' array bytes stays
under ``max_bytes``, so what a process holds depends on the sizes of the databases it serves, not on
how many jobs ran before: a job's memory limit is met or not whatever earlier jobs used. A database
larger than the whole bound is loaded for its job and not kept.

The weight of an engine is its database's array bytes (``nbytes`` summed), not a measurement of
the engine's objects: it is known before loading, the same in every process, and an upper bound on
the mapped part (what an engine derives at load is of the same order or smaller: a graph engine
keeps the mapped arrays as they are and derives its edge transforms, 40 bytes an edge).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from typing import Any

from cachetools import LRUCache

from engines.base import AnyEngine

OpenArrays = Callable[[str], Mapping[str, Any]]
"""``open_arrays(db_id)``: a database's arrays by name (e.g. ``Store.database_arrays``)."""

MiB = 1 << 20


def arrays_bytes(arrays: Mapping[str, Any]) -> int:
    """Bytes of a database's arrays (mapped or in memory)."""
    return int(sum(int(getattr(a, "nbytes", 0)) for a in arrays.values()))


class EngineCache:
    """Loaded engines by (database id, engine name), at most ``max_bytes`` of database arrays
    (one per process: each engine process, and the API process for live sessions).

    ``get`` loads an engine on a miss with ``open_arrays(db_id)``; it is safe to call from several
    threads (two misses of one key may both load; one is kept)."""

    def __init__(self, max_bytes: int = 2048 * MiB) -> None:
        self.max_bytes = max_bytes
        self._sizes: dict[tuple[str, str], int] = {}
        self._engines: LRUCache[tuple[str, str], AnyEngine] = LRUCache(
            maxsize=max(max_bytes, 1), getsizeof=lambda _e: 0
        )
        self._lock = threading.Lock()

    def get(self, db_id: str, engine_cls: type[AnyEngine], open_arrays: OpenArrays) -> AnyEngine:
        key = (db_id, engine_cls.name)
        with self._lock:
            engine = self._engines.get(key)
        if engine is not None:
            return engine
        arrays = open_arrays(db_id)
        size = arrays_bytes(arrays)
        engine = engine_cls.load(dict(arrays))
        self._put(key, engine, size)
        return engine

    def _put(self, key: tuple[str, str], engine: AnyEngine, size: int) -> None:
        with self._lock:
            if size > self.max_bytes:
                return
            while self._engines and self.held_bytes + size > self.max_bytes:
                old, _ = self._engines.popitem()
                self._sizes.pop(old, None)
            self._engines[key] = engine
            self._sizes[key] = size

    @property
    def held_bytes(self) -> int:
        """Array bytes of the engines kept."""
        return sum(self._sizes.values())

    def __len__(self) -> int:
        return len(self._engines)

    def __contains__(self, key: object) -> bool:
        return key in self._engines

    def clear(self) -> None:
        with self._lock:
            self._engines.clear()
            self._sizes.clear()
