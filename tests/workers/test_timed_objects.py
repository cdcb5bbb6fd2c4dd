"""workers.timed_objects: no store call waits on a stalled store past its limit."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import pytest

from workers.objects import LocalObjects
from workers.storage_errors import StoreTimeout, storage_problem
from workers.store import Store
from workers.timed_objects import TimedObjects, untimed

GUARD_S = 60.0


class Gate:
    """A local store whose ``get`` waits until ``opened`` (at most :data:`GUARD_S`)."""

    def __init__(self, inner: LocalObjects) -> None:
        self.inner, self.url = inner, inner.url
        self.opened = threading.Event()
        self.calls = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def get(self, key: str) -> bytes:
        self.calls += 1
        self.opened.wait(GUARD_S)
        return self.inner.get(key)


def test_a_stalled_call_times_out_and_queued_ones_never_run(tmp_path: Path) -> None:
    local = LocalObjects(tmp_path)
    local.put("a/b", b"x")
    gate = Gate(local)
    timed = TimedObjects(gate, 0.2, threads=1)
    try:
        with pytest.raises(StoreTimeout) as stalled:
            timed.get("a/b")
        assert storage_problem(stalled.value) is not None  # an OSError the API recognises
        with pytest.raises(StoreTimeout):
            timed.get("a/b")  # queued behind the stalled one: given up, then cancelled
        gate.opened.set()
        assert timed.get("a/b") == b"x"
        assert gate.calls == 2  # the cancelled call never reached the store
        assert timed.exists("a/b") and timed.children("a") == ["b"]
    finally:
        gate.opened.set()
        timed.close()


def test_a_store_works_through_it(tmp_path: Path) -> None:
    """Holders (which pick their protocol by the backend's kind) and streamed puts go through."""
    store = Store(tmp_path)
    timed = TimedObjects(store.objects, 30.0)
    store.objects = timed
    try:
        assert untimed(timed) is timed.inner
        info = store.put_file("song.mid", b"MThd" + b"\0" * 100)
        assert store.add_owner("files", info.id, "alice", {"name": "song.mid"})
        assert store.owners("files", info.id) == {"alice"}
        assert store.file_bytes(info.id) == b"MThd" + b"\0" * 100
    finally:
        timed.close()
