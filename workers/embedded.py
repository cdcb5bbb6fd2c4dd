"""The embedded backend (default, no Redis): jobs run in a local pool of spawned processes.

Worker processes publish events through a multiprocessing queue; a thread in the API process
drains it into the :class:`~workers.backend.EventHub` and the job's ``events.jsonl`` and
``info.json`` in the store (so finished jobs can be replayed after a restart). Cancellation is a
flag file the worker polls through ``should_stop``.
"""

from __future__ import annotations

import asyncio
import json
import logging
import multiprocessing as mp
import os
import threading
import time
from collections.abc import AsyncIterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from schemas import DatabaseStatus, EventType, JobEvent, JobInfo, JobStatus
from schemas.jobs import JobKind

from .backend import EventHub
from .execute import EngineCache, apply_event, execute_job
from .store import NotFoundError, Store

log = logging.getLogger("segue.embedded")

# -- worker process side -------------------------------------------------------------------------
_STORE: Store | None = None
_QUEUE: Any = None
_CACHE = EngineCache()


def _init_worker(root: str, queue: Any) -> None:
    global _STORE, _QUEUE
    from engines.registry import load_plugins
    from motion.allocator import tune_process

    tune_process()
    load_plugins()
    _STORE, _QUEUE = Store(root), queue


def _cancel_flag(store: Store, job_id: str) -> Path:
    return store.job_dir(job_id) / "cancel"


def _run_job(job_id: str, kind: str, payload: dict[str, Any]) -> None:
    assert _STORE is not None and _QUEUE is not None
    store, queue = _STORE, _QUEUE
    flag = _cancel_flag(store, job_id)
    last_check = [0.0, False]

    def should_stop() -> bool:
        now = time.monotonic()
        if not last_check[1] and now - last_check[0] > 0.02:
            last_check[0], last_check[1] = now, flag.exists()
        return bool(last_check[1])

    def publish(type_: EventType, data: dict[str, Any]) -> None:
        queue.put((job_id, type_.value, data, time.time()))

    execute_job(store, job_id, kind, payload, publish, should_stop, _CACHE)


def _warm_up() -> int:
    return os.getpid()


# -- API process side ----------------------------------------------------------------------------
class EmbeddedBackend:
    """Jobs in a local process pool (see the module docstring)."""

    def __init__(self, store: Store, workers: int = 2) -> None:
        self.store = store
        self.workers = max(1, workers)
        self.hub = EventHub()
        self._ctx = mp.get_context("spawn")
        self._queue: Any = None
        self._pool: ProcessPoolExecutor | None = None
        self._drain: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._running: set[str] = set()
        self._tasks: set[asyncio.Future[JobEvent]] = set()

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._queue = self._ctx.Queue()
        self._pool = ProcessPoolExecutor(
            max_workers=self.workers,
            mp_context=self._ctx,
            initializer=_init_worker,
            initargs=(str(self.store.root), self._queue),
        )
        # start every worker now (spawn + imports take ~1 s) so the first job does not wait
        await asyncio.gather(*(self._loop.run_in_executor(self._pool, _warm_up) for _ in range(self.workers)))
        self._drain = threading.Thread(target=self._drain_queue, name="segue-events", daemon=True)
        self._drain.start()
        await self._fail_stale_jobs()

    async def close(self) -> None:
        """Cancel running jobs, stop the pool and the event thread (without blocking the loop)."""
        if self._pool is not None:
            for job_id in list(self._running):
                _cancel_flag(self.store, job_id).touch()
            pool, self._pool = self._pool, None
            await asyncio.to_thread(pool.shutdown, True, cancel_futures=True)
        if self._queue is not None:
            queue, self._queue = self._queue, None
            queue.put(None)
            if self._drain is not None:
                await asyncio.to_thread(self._drain.join, 10)

    async def _fail_stale_jobs(self) -> None:
        """Jobs left queued/running by a previous server process can never finish: fail them
        (and the databases they were building) so clients are not left waiting."""
        for info in self.store.list_jobs():
            if info.status.finished:
                continue
            await self._replay_from_disk(info.id)
            error = {
                "error": {"code": "server_restarted", "message": "the server restarted before the job ended"}
            }
            await self._record(info.id, EventType.failed, error, time.time())
            if info.kind == JobKind.build and info.database:
                try:
                    db = self.store.database_info(info.database)
                except NotFoundError:
                    continue
                if db.status in (DatabaseStatus.queued, DatabaseStatus.building):
                    self.store.put_database_info(
                        db.model_copy(update={"status": DatabaseStatus.failed, "error": "server restarted"})
                    )

    def _drain_queue(self) -> None:
        queue = self._queue
        while True:
            item = queue.get()
            if item is None:
                return
            job_id, type_, data, when = item
            assert self._loop is not None
            fut = asyncio.run_coroutine_threadsafe(
                self._record(job_id, EventType(type_), data, when), self._loop
            )
            try:
                fut.result(timeout=30)
            except Exception:  # the loop is closing
                log.exception("could not record an event of job %s", job_id)

    async def _record(self, job_id: str, type_: EventType, data: dict[str, Any], when: float) -> JobEvent:
        event = self.hub.make_event(job_id, type_, data, when)
        await self.hub.append(event)
        job_dir = self.store.job_dir(job_id)
        with open(job_dir / "events.jsonl", "a", encoding="utf-8") as fh:
            fh.write(event.model_dump_json() + "\n")
        info = apply_event(self.store.job_info(job_id), type_, data, event.id)
        self.store.put_job(info)
        if type_.terminal:
            self._running.discard(job_id)
        return event

    async def submit(self, info: JobInfo, kind: str, payload: dict[str, Any]) -> JobInfo:
        if self._pool is None or self._loop is None:
            raise RuntimeError("the embedded backend is not started")
        self._running.add(info.id)
        await self._record(info.id, EventType.queued, {}, time.time())
        future = self._loop.run_in_executor(self._pool, _run_job, info.id, kind, payload)
        future.add_done_callback(lambda f, job_id=info.id: self._finished(job_id, f))
        return self.store.job_info(info.id)

    def _finished(self, job_id: str, future: asyncio.Future[None]) -> None:
        exc = future.exception() if not future.cancelled() else None
        if exc is not None or future.cancelled():
            # the worker process died (or the pool shut down) before a terminal event
            msg = "worker process ended unexpectedly" if exc is not None else "backend shut down"
            log.error("job %s: %s (%r)", job_id, msg, exc)
            if not self.hub.log(job_id).terminal and self._loop is not None and not self._loop.is_closed():
                task = asyncio.ensure_future(
                    self._record(
                        job_id,
                        EventType.failed,
                        {"error": {"code": "worker_lost", "message": msg}},
                        time.time(),
                    )
                )
                self._tasks.add(task)
                task.add_done_callback(self._tasks.discard)

    async def status(self, job_id: str) -> JobInfo:
        return self.store.job_info(job_id)

    async def cancel(self, job_id: str) -> JobInfo:
        info = self.store.job_info(job_id)
        if not info.status.finished:
            _cancel_flag(self.store, job_id).touch()
        return info

    async def _replay_from_disk(self, job_id: str) -> None:
        path = self.store.job_dir(job_id) / "events.jsonl"
        if self.hub.has(job_id) or not path.exists():
            return
        for line in path.read_text(encoding="utf-8").splitlines():
            if line.strip():
                await self.hub.append(JobEvent.model_validate(json.loads(line)))

    async def events(self, job_id: str, after: int = 0) -> AsyncIterator[JobEvent]:
        self.store.job_info(job_id)  # NotFoundError for unknown jobs
        await self._replay_from_disk(job_id)
        info = self.store.job_info(job_id)
        if info.status.finished and not self.hub.log(job_id).terminal:
            return  # finished before this process kept its log and left none on disk
        async for event in self.hub.follow(job_id, after):
            yield event

    async def health(self) -> dict[str, Any]:
        return {"backend": "embedded", "workers": self.workers, "running_jobs": len(self._running)}


__all__ = ["EmbeddedBackend", "JobStatus", "NotFoundError"]
