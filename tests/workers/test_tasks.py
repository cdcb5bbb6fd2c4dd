"""Small jobs through the Redis backend: a ``segue worker`` parses an upload and makes an export
for the API (:mod:`workers.tasks`, awaited by :class:`service.tasks.TaskRunner`), with the bytes
the API would have made, and the small job is gone afterwards."""

from __future__ import annotations

import gzip
import io
from pathlib import Path
from typing import Any

import pytest

from motion import write_bvh
from motion.export.glb import glb_bytes
from motion.io import load_motion
from schemas import EventType
from service.errors import ApiError
from service.metrics import Metrics
from service.tasks import TaskRunner
from tests.motion.retarget.characters import character
from workers.execute import EngineCache, execute_job
from workers.redis_backend import RedisBackend
from workers.result_export import CharacterRef, ExportSpec, ResultFormat, make_export
from workers.store import NotFoundError, Store
from workers.tasks import run_task, task_payload

from .conftest import add_database, run, synth, worker_thread


def _walk_result(store: Store) -> tuple[str, str]:
    db = add_database(store)
    job, payload = synth(store, db, steps=1, step_s=0.01)
    events: list[tuple[Any, dict[str, Any]]] = []
    execute_job(
        store, job.id, "synth", payload, lambda t, d: events.append((t, d)), lambda: False, EngineCache()
    )
    return job.id, str(events[-1][1]["result"])


def test_redis_workers_run_small_jobs(redis_url: str, store: Store) -> None:
    job_id, rid = _walk_result(store)
    buf = io.StringIO()
    write_bvh(character("mixamo", scale=1.1), buf)
    char_bytes = gzip.compress(buf.getvalue().encode())
    store.put_staged("up1", char_bytes)
    limits = [1024, 2_000_000, 1 << 28]

    async def scenario() -> tuple[dict[str, Any], dict[str, Any], ApiError]:
        backend = RedisBackend(store, redis_url)
        await backend.start()
        runner, metrics = TaskRunner(), Metrics()
        try:
            clip = await runner.run(
                "clip:up1",
                task_payload("clip", staged="up1", name="char.bvh.gz", units=None, limits=limits),
                store,
                backend,
                metrics,
            )
            spec = ExportSpec(
                job=job_id,
                result=rid,
                format=ResultFormat.bvh,
                character=CharacterRef("clip", clip["clip"]["id"], "char.bvh.gz", "char.bvh.gz", "cm"),
            )
            done = await runner.run(
                "export:1", task_payload("export", spec=spec.to_dict()), store, backend, metrics
            )
            store.put_staged("up2", b"HIERARCHY\nROOT x\n{\n")
            with pytest.raises(ApiError) as bad:
                await runner.run(
                    "clip:up2",
                    task_payload("clip", staged="up2", name="bad.bvh", units=None, limits=limits),
                    store,
                    backend,
                    metrics,
                )
            await runner.idle()
            return clip, {**done, "spec": spec}, bad.value
        finally:
            await backend.close()

    with worker_thread(redis_url, store, "t1"):
        clip, done, bad = run(scenario())
    assert clip["clip"]["name"] == "char.bvh.gz" and store.clip_bytes(clip["clip"]["id"]) == char_bytes
    spec = done["spec"]
    with store.open_export(job_id, done["export"]) as fh:
        assert fh.read() == make_export(store, spec)
    assert bad.status == 400 and bad.code == "invalid_bvh"
    assert [j.kind for j in store.list_jobs()] == ["synth"]  # the small jobs were removed
    for key in ("up1", "up2"):
        with pytest.raises(NotFoundError):
            store.staged_bytes(key)


class _UnreachableResults(Store):
    """A store whose object service stops answering when a result is written."""

    def put_result(self, *args: Any, **kwargs: Any) -> None:
        from workers.objects import StoreUnavailable

        raise StoreUnavailable("object store http://s3.invalid unreachable: connect timeout")


def test_a_store_failure_during_a_run_is_named_not_internal(tmp_path: Path) -> None:
    store = _UnreachableResults(tmp_path / "data")
    db = add_database(store)
    job, payload = synth(store, db, steps=1, step_s=0.01)
    events: list[tuple[Any, dict[str, Any]]] = []
    execute_job(
        store, job.id, "synth", payload, lambda t, d: events.append((t, d)), lambda: False, EngineCache()
    )
    kind, data = events[-1]
    assert kind == EventType.failed
    assert data["error"]["code"] == "storage_unavailable"
    assert "cannot be reached" in data["error"]["message"]


def test_a_staged_gltf_that_cannot_be_read_fails_as_gltf(tmp_path: Path) -> None:
    # a glTF upload over the inline size is parsed by a small job: its fault is named as glTF
    store = Store(tmp_path / "data")
    cut = glb_bytes(load_motion("sample:walk").to_units("m"))[:5000]
    events: list[tuple[EventType, dict[str, Any]]] = []
    key = store.stage(cut)
    limits = [100, 100_000, 10_000_000, 10_000_000]
    request = task_payload("clip", staged=key, name="cut.glb", units=None, limits=limits)["request"]
    run_task(store, request, lambda kind, data: events.append((kind, data)))
    ((kind, data),) = events
    assert kind is EventType.failed and data["error"]["code"] == "invalid_gltf", data
    assert "cut.glb" in data["error"]["message"]
