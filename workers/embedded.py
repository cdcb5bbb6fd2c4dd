"""The embedded backend (default, no Redis): jobs run in supervised engine processes of the API.

``workers`` :class:`~workers.supervisor.EngineProcess` children run the jobs; their watch threads
relay each event into the :class:`~workers.backend.EventHub` and the job's ``events.jsonl`` and
``info.json`` in the store. Jobs wait in an in-memory queue for an idle process.

Recovery (the store's job records are the source of truth):

* a child that dies (SIGKILL, the OOM killer) is replaced at once and its job re-run, with a new
  ``started`` event (``attempt`` n) and the same event ids, up to ``max_attempts`` runs
  (then ``failed`` with code ``worker_lost``); the other processes and jobs are not touched;
* every event carries the attempt of the run that published it (0 before any run), and only the
  job's current run is recorded (the supervisor also drops a replaced child's late messages), as
  the Redis backend's fence does across hosts (:mod:`workers.fencing`);
* a build's terminal event leaves its database ``ready`` or ``failed`` with the reason
  (:func:`workers.records.settle_database`), and a small job's staged upload is removed;
* at start-up, jobs a previous server process left ``queued`` or ``running`` are queued again, their
  events replayed from ``events.jsonl`` so clients resume with ``after=`` where they were;
* the supervisor kills a job that ignores its cancel for ``cancel_grace_s``, runs past its time limit
  (``budget_s`` + ``time_grace_s``) or past ``max_rss_bytes`` of memory (see
  :func:`~workers.supervisor.terminal_after_kill`).

``health()`` reports the processes alive and ready, restarts, the queue and running jobs; it is an
error (``/healthz`` 503) when no engine process is alive and none can start.

Jobs wait in a :class:`~workers.fair_queue.FairQueue`: one line per principal, served round-robin,
so one principal's backlog delays another's next job by at most the job each process is running.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections.abc import AsyncIterator
from typing import Any

from schemas import DatabaseStatus, EventType, JobEvent, JobInfo, JobStatus
from schemas.jobs import JobKind

from .backend import BackendUnavailable, EventHub, JobNotFinished
from .budget import shortfall
from .execute import apply_event
from .fair_queue import FairQueue
from .records import settle, sweep_staged
from .settings import Settings
from .store import NotFoundError, Store
from .supervisor import (
    ChildConfig,
    EngineProcess,
    Outcome,
    Task,
    engine_plugins,
    terminal_after_kill,
    time_limit,
)

log = logging.getLogger("segue.embedded")


CACHE_FULL_MESSAGE = (
    "the server has no room in its local cache for this job's database (its disk is full; the "
    "operator is told in the server log); nothing is wrong with the request: submit it again later"
)


class EmbeddedBackend:
    """Jobs in local supervised engine processes (see the module docstring)."""

    @classmethod
    def from_settings(cls, store: Store, settings: Settings) -> EmbeddedBackend:
        """The backend ``segue serve`` runs: ``workers`` processes with the settings' job limits."""
        return cls(
            store,
            settings.workers,
            cancel_grace_s=settings.cancel_grace_s,
            time_grace_s=settings.job_grace_s,
            build_timeout_s=settings.build_timeout_s,
            max_rss_bytes=settings.max_rss_bytes,
            plugins=settings.engine_plugins,
            engine_cache_bytes=settings.engine_cache_mb << 20,
            load_timeout_s=settings.load_timeout_s,
            staged_max_age_s=settings.staged_max_age_s,
            staged_sweep_s=settings.staged_sweep_s,
        )

    def __init__(
        self,
        store: Store,
        workers: int = 2,
        *,
        max_attempts: int = 3,
        cancel_grace_s: float = 2.0,
        time_grace_s: float = 30.0,
        build_timeout_s: float = 3600.0,
        max_rss_bytes: int | None = None,
        plugins: str | None = None,
        engine_cache_bytes: int = 2048 << 20,
        load_timeout_s: float | None = 300.0,
        staged_max_age_s: float = 3600.0,
        staged_sweep_s: float = 300.0,
    ) -> None:
        self.store = store
        self.plugins, self.engine_cache_bytes = plugins, engine_cache_bytes
        self.load_timeout_s = load_timeout_s
        self.workers = max(1, workers)
        self.max_attempts = max_attempts
        self.cancel_grace_s, self.time_grace_s = cancel_grace_s, time_grace_s
        self.build_timeout_s, self.max_rss_bytes = build_timeout_s, max_rss_bytes
        self.hub = EventHub()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._processes: list[EngineProcess] = []
        self._queue: FairQueue[Task] = FairQueue(lambda task: task.owner)
        """Waiting jobs, served round-robin by principal (:mod:`workers.fair_queue`)."""
        self._running: dict[str, Task] = {}
        self._attempts: dict[str, int] = {}
        """The current run of each job (its latest dispatched attempt): only its events are recorded."""
        self._closing = False
        self.reruns = 0
        self.staged_max_age_s, self.staged_sweep_s = staged_max_age_s, staged_sweep_s
        self._sweeper: asyncio.Task[None] | None = None

    # -- lifecycle ------------------------------------------------------------------------------
    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        config = ChildConfig(
            store_root=self.store.url,
            plugins=engine_plugins(self.plugins),
            engine_cache_bytes=self.engine_cache_bytes,
            cache_dir=str(self.store.root),
            disk_cache_bytes=self.store.cache.max_bytes,
        )
        for i in range(self.workers):
            process = EngineProcess(
                f"embedded-{i}",
                config,
                self._on_event,
                self._on_end,
                cancel_grace_s=self.cancel_grace_s,
                max_rss_bytes=self.max_rss_bytes,
                load_timeout_s=self.load_timeout_s,
                on_ready=self._on_ready,
                spawner=self._on_loop,
            )
            process.start()
            self._processes.append(process)
        # spawning + imports take ~1 s: wait (off the loop) so the first job does not
        for process in self._processes:
            await asyncio.to_thread(process.ready.wait, 120)
        await self._requeue_unfinished()
        self._dispatch()
        self._sweeper = asyncio.create_task(self._sweep_loop(), name="segue-staged-sweep")

    async def _sweep_loop(self) -> None:
        """Every ``staged_sweep_s``: remove orphaned staged uploads (off the event loop)."""
        while True:
            await asyncio.to_thread(sweep_staged, self.store, self.staged_max_age_s)
            await asyncio.sleep(self.staged_sweep_s)

    async def close(self) -> None:
        """Stop the engine processes (running jobs stay ``running`` on disk and are re-queued by the
        next server process)."""
        self._closing = True
        if self._sweeper is not None:
            self._sweeper.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._sweeper
            self._sweeper = None
        processes, self._processes = self._processes, []
        await asyncio.gather(*(asyncio.to_thread(p.close) for p in processes))

    # -- recovery -------------------------------------------------------------------------------
    async def _requeue_unfinished(self) -> None:
        """Queue again the jobs a previous server process left unfinished (the store is the truth)."""
        for info in self.store.list_jobs():
            if info.status.finished:
                continue
            await self._replay_from_disk(info.id)
            try:
                request = self.store.job_request(info.id)
            except NotFoundError:
                await self._fail(info.id, "lost", "the job's request is missing from the store")
                continue
            attempts = sum(1 for e in self.hub.log(info.id).events if e.type == EventType.started)
            self._attempts[info.id] = attempts
            if attempts >= self.max_attempts:
                await self._fail(
                    info.id, "worker_lost", f"the job was started {attempts} times and never ended"
                )
                continue
            log.warning("re-queueing job %s left %s by a previous server process", info.id, info.status.value)
            if info.kind == JobKind.build and info.database:
                self._reset_database(info.database)
            self._queue.append(
                self._task(info.id, str(request["kind"]), dict(request["payload"]), attempts + 1, info.owner)
            )
            self.reruns += 1

    def _reset_database(self, db_id: str) -> None:
        try:
            db = self.store.database_info(db_id)
        except NotFoundError:
            return
        if db.status == DatabaseStatus.building:
            self.store.put_database_info(db.model_copy(update={"status": DatabaseStatus.queued}))

    def _task(
        self, job_id: str, kind: str, payload: dict[str, Any], attempt: int, owner: str | None = None
    ) -> Task:
        limit = time_limit(kind, payload, self.time_grace_s, self.build_timeout_s)
        return Task(job_id, kind, payload, attempt=attempt, time_limit_s=limit, owner=owner)

    # -- dispatch (event loop) --------------------------------------------------------------------
    def _dispatch(self) -> None:
        if self._closing:
            return
        for process in self._processes:
            if not self._queue:
                return
            if process.idle:
                task = self._queue.pop()
                if process.run(task):
                    self._running[task.job_id] = task
                    self._attempts[task.job_id] = task.attempt
                else:
                    self._queue.unpop(task)

    def _on_event(self, task: Task, type_: EventType, data: dict[str, Any], when: float) -> None:
        """Watch thread: relay an event of a running job (waits until it is recorded)."""
        if type_ == EventType.started:
            data = {**data, "attempt": task.attempt}
        elif type_ == EventType.done and task.kind == "synth":
            short = shortfall(self.store, task.job_id, task.payload, data.get("result"))
            if short is not None:
                data = {**data, "short": short}
        self._call(self._record(task.job_id, type_, data, when, attempt=task.attempt))

    def _on_loop(self, start: Any) -> None:
        """Watch thread: start a child from the event loop's thread (the server's main thread)."""
        loop = self._loop
        if loop is None or loop.is_closed():
            raise RuntimeError("the event loop is closed")

        async def call() -> None:
            start()

        asyncio.run_coroutine_threadsafe(call(), loop).result(timeout=60)

    def _on_ready(self) -> None:
        """Watch thread: a (re)started process can take a queued job."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._dispatch)

    def _on_end(self, task: Task, outcome: Outcome, detail: str) -> None:
        """Watch thread: a task is over (see :mod:`workers.supervisor` for the outcomes)."""
        self._call(self._ended(task, outcome, detail))

    def _call(self, coro: Any) -> None:
        loop = self._loop
        if loop is None or loop.is_closed():
            coro.close()
            return
        try:
            asyncio.run_coroutine_threadsafe(coro, loop).result(timeout=60)
        except Exception:
            log.exception("the event loop could not take a job update")

    async def _ended(self, task: Task, outcome: Outcome, detail: str) -> None:
        self._running.pop(task.job_id, None)
        try:
            if outcome == "released":  # this host's cache disk: every engine process here shares it
                log.error("job %s: %s", task.job_id, detail)
                await self._fail(task.job_id, "cache_full", CACHE_FULL_MESSAGE)
            elif outcome == "finished":
                if not task.terminal:
                    await self._fail(task.job_id, "internal", "the job ended without a terminal event")
            elif outcome == "crashed":
                if self._closing:
                    return  # the server stops: the next one re-queues the job from the store
                if task.terminal:
                    return
                if task.cancel_asked is not None:
                    await self._record(task.job_id, EventType.cancelled, {"result": task.best}, time.time())
                elif task.attempt >= self.max_attempts:
                    await self._fail(
                        task.job_id, "worker_lost", f"{detail}; gave up after {task.attempt} attempts"
                    )
                else:
                    log.warning(
                        "job %s: %s; running it again (attempt %d)", task.job_id, detail, task.attempt + 1
                    )
                    self.reruns += 1
                    again = self._task(task.job_id, task.kind, task.payload, task.attempt + 1, task.owner)
                    self._queue.appendleft(again)
            elif not task.terminal:
                type_, data = terminal_after_kill(outcome, task, detail)
                await self._record(task.job_id, type_, data, time.time())
        finally:
            self._dispatch()

    async def _fail(self, job_id: str, code: str, message: str) -> None:
        await self._record(
            job_id, EventType.failed, {"error": {"code": code, "message": message}}, time.time()
        )

    async def _record(
        self, job_id: str, type_: EventType, data: dict[str, Any], when: float, attempt: int | None = None
    ) -> JobEvent | None:
        """Record an event of run ``attempt`` (None: the backend's own, for the current run);
        refused when the job already ended or another run holds it."""
        if self.hub.log(job_id).terminal:
            return None  # exactly one terminal event, nothing after it
        current = self._attempts.get(job_id, 0)
        if attempt is not None and attempt != current:
            log.warning(
                "job %s: %s of attempt %d refused (%d holds it)", job_id, type_.value, attempt, current
            )
            return None
        event = self.hub.make_event(job_id, type_, data, when, attempt=current)
        await self.hub.append(event)
        self.store.append_event(job_id, event.model_dump_json())
        info = apply_event(self.store.job_info(job_id), type_, data, event.id)
        self.store.put_job(info)
        if type_.terminal:
            self._attempts.pop(job_id, None)
            settle(self.store, info, event)
        return event

    # -- the backend protocol ---------------------------------------------------------------------
    async def submit(self, info: JobInfo, kind: str, payload: dict[str, Any]) -> JobInfo:
        if self._loop is None or self._closing:
            raise BackendUnavailable("the embedded backend is not running")
        if not any(p.ready.is_set() or p.failed_starts < 3 for p in self._processes):
            raise BackendUnavailable("no engine process is alive and none could start")
        await self._record(info.id, EventType.queued, {}, time.time())
        self._queue.append(self._task(info.id, kind, payload, 1, info.owner))
        self._dispatch()
        return await self.status(info.id)

    async def status(self, job_id: str) -> JobInfo:
        return await asyncio.to_thread(self.store.job_info, job_id)  # a file read: off the event loop

    async def cancel(self, job_id: str) -> JobInfo:
        info = await self.status(job_id)
        if info.status.finished:
            return info
        queued = next((t for t in self._queue if t.job_id == job_id), None)
        if queued is not None:
            self._queue.remove(queued)
            await self._record(job_id, EventType.cancelled, {"result": info.result}, time.time())
        else:
            for process in self._processes:
                if process.cancel(job_id):
                    break
        return await self.status(job_id)

    async def delete(self, job_id: str) -> None:
        info = await self.status(job_id)
        if not info.status.finished or job_id in self._running:
            raise JobNotFinished(f"job {job_id} is {info.status.value}")
        self.hub.forget(job_id)
        await asyncio.to_thread(self.store.delete_job, job_id)

    async def backlog(self, job_id: str, after: int = 0) -> list[JobEvent]:
        await self.status(job_id)  # NotFoundError for unknown jobs
        await self._replay_from_disk(job_id)
        return [e for e in self.hub.log(job_id).events if e.id > after]

    async def _replay_from_disk(self, job_id: str) -> None:
        """The events a previous server process archived (read in a worker thread; a concurrent
        replay's duplicates are ignored by the hub). A log this process holds events in is whole:
        its jobs record every event in the hub first."""
        if self.hub.has(job_id) and self.hub.log(job_id).events:
            return
        for event in await asyncio.to_thread(self._archived, job_id):
            await self.hub.append(event)

    def _archived(self, job_id: str) -> list[JobEvent]:
        return [JobEvent.model_validate(json.loads(line)) for line in self.store.events(job_id)]

    async def events(self, job_id: str, after: int = 0) -> AsyncIterator[JobEvent]:
        await self.status(job_id)  # NotFoundError for unknown jobs
        await self._replay_from_disk(job_id)
        info = await self.status(job_id)
        if info.status.finished and not self.hub.log(job_id).terminal:
            return  # finished before this process kept its log and left none on disk
        async for event in self.hub.follow(job_id, after):
            yield event

    async def health(self) -> dict[str, Any]:
        alive = sum(1 for p in self._processes if p.ready.is_set())
        facts: dict[str, Any] = {
            "backend": "embedded",
            "workers": self.workers,
            "workers_ready": alive,
            "running_jobs": len(self._running),
            "queued": len(self._queue),
            "restarts": sum(p.restarts for p in self._processes),
            "reruns": self.reruns,
        }
        if alive == 0 and all(p.failed_starts >= 3 for p in self._processes):
            facts["error"] = "no engine process is alive and none could start"
        return facts


__all__ = ["EmbeddedBackend", "JobStatus", "NotFoundError"]
