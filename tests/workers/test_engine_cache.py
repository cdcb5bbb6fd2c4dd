"""The engine cache holds databases by bytes, and a database load is not charged to the job's time."""

from __future__ import annotations

import time
from typing import Any

from engines.registry import engine_class
from workers.engine_cache import EngineCache, arrays_bytes
from workers.store import Store
from workers.supervisor import ChildConfig, EngineProcess, Task

from .conftest import add_database


def test_kept_engines_are_bounded_by_their_databases_bytes(store: Store) -> None:
    dbs = [add_database(store, fps=fps) for fps in (30.0, 15.0, 10.0)]
    sizes = {db: arrays_bytes(store.database_arrays(db)) for db in dbs}
    scripted = engine_class("scripted")
    opened: list[str] = []

    def open_arrays(db_id: str) -> Any:
        opened.append(db_id)
        return store.database_arrays(db_id)

    cache = EngineCache(max_bytes=sizes[dbs[0]] + sizes[dbs[1]])
    first = cache.get(dbs[0], scripted, open_arrays)
    assert cache.get(dbs[0], scripted, open_arrays) is first and opened == [dbs[0]]
    cache.get(dbs[1], scripted, open_arrays)
    assert cache.held_bytes == sizes[dbs[0]] + sizes[dbs[1]]
    cache.get(dbs[0], scripted, open_arrays)  # dbs[1] is now the least recently used
    cache.get(dbs[2], scripted, open_arrays)
    assert (dbs[0], "scripted") in cache and (dbs[1], "scripted") not in cache
    assert cache.held_bytes <= cache.max_bytes
    tiny = EngineCache(max_bytes=1)  # larger than the bound: loaded for its job, not kept
    assert tiny.get(dbs[0], scripted, open_arrays) is not None and len(tiny) == 0


def test_the_job_clock_stops_while_its_database_loads(store: Store) -> None:
    ended: list[str] = []
    process = EngineProcess(
        "t", ChildConfig(store_root=store.url), lambda *a: None, lambda t, o, d: ended.append(o)
    )
    task = Task("j1", "synth", {}, time_limit_s=10.0, seq=1, started=time.monotonic())
    process._task = task
    process._handle(("load", 1, True, 0.0))
    assert task.loading_since is not None
    before = task.started
    time.sleep(0.05)
    process._handle(("load", 1, False, 0.0))
    assert task.loading_since is None and task.started >= before + 0.05
    process._handle(("load", 2, True, 0.0))  # another task's message: ignored
    assert task.loading_since is None
