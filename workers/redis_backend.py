"""The Redis job backend (``SEGUE_REDIS_URL``): the API side of the distributed runtime.

Jobs run in ``segue worker`` processes (:mod:`workers.redis_worker`); this module gives the API the
same semantics as the embedded backend (event ids from 1, resume with ``after``, cancel keeps the
best result, every job ends with exactly one of ``done``/``failed``/``cancelled``). Keys are listed in
:mod:`workers.redis_keys`; events are published with :mod:`workers.redis_events`.

- **submit**: ``SET segue:job:<job> <JobInfo> NX`` (a second submit of the same job id is a no-op:
  jobs are idempotent), the ``queued`` event (id 1), then the job on its principal's waiting list
  (:mod:`workers.redis_queue`: served round-robin; the entry stamped with this API's version,
  :mod:`workers.version`), and the ``queued`` event written to the store's archive.
- **status**: the JobInfo in Redis, else the store's ``info.json`` (kept in step by every publisher).
- **cancel**: ``SET segue:cancel:<job> 1 EX``; the worker's ``should_stop`` sees it within ~50 ms and
  the job ends ``cancelled`` with its best result. A job still queued ends ``cancelled`` at once (the
  worker that later receives it finds the terminal marker and skips it); the API's ``cancelled`` is
  published with attempt 0, so it is refused if a run started meanwhile (that run ends it).
- **events**: one reader task per job per API process ``XRANGE``\\ s the job's stream after the hub's
  last event id (entry ids are ``<event id>-0``), then follows it until the terminal event, appending
  to the :class:`~workers.backend.EventHub`; any number of sockets follow the hub. The blocking part
  is shared: one ``XREAD BLOCK`` over every followed job's stream (:class:`_StreamPump`), so an API
  process holds one blocked connection, not one per job (redis-py pools default to 100
  connections). Events Redis lost (a restart without persistence, a flush) are read from the
  store's archive (:mod:`workers.event_archive`): a reader never keeps a gap it can fill.
  ``GET /events`` (:meth:`RedisBackend.backlog`) reads Redis again before it answers, so once the
  status says a job ended its terminal event is in the answer.
- **health**: live workers (heartbeat keys), queue length, pending entries, dead letters; an error
  (``/healthz`` 503) while Redis is unreachable.
- **reconcile** (at start and every ``reconcile_s``): the store's job records are the source of
  truth. An unfinished job Redis does not know (``segue:job:<job>`` missing: Redis restarted without
  persistence, or restored an older snapshot) and that no live worker names in its heartbeat is
  queued again once it has been missing for ``requeue_after_s`` (longer than a worker's heartbeat
  period, so a worker still running it re-announces it first); its event counter is set to the last
  id clients may have seen, so the re-run's events follow them. The stream and its group are
  recreated when missing. A job Redis says ended while the store does not (its publisher died
  between the two) gets its store records written here (:func:`_write_records`).
- **submit while Redis is down** raises :class:`~workers.backend.BackendUnavailable` (503, and the
  API removes the job's record).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import logging
import uuid
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any, cast

import redis
import redis.asyncio as aredis

from schemas import EventType, JobEvent, JobInfo, JobStatus

from .backend import BackendUnavailable, EventHub, JobLog, JobNotFinished
from .event_archive import archive_event, archive_events, merge, read_archive
from .fencing import StaleAttempt
from .records import put_job_record, settle
from .redis_events import RETENTION_S, AsyncEventPublisher, Entries, decode_event, stream_id
from .redis_keys import DEFAULT_PREFIX, RedisKeys
from .redis_queue import BELL_MAX, SUBMIT_LUA, principal_list, queue_entry
from .store import NotFoundError, Store
from .version import describe, stamp

log = logging.getLogger("segue.redis.backend")


class RedisBackend:
    """Jobs through Redis streams, run by ``segue worker`` processes (see the module docstring)."""

    def __init__(
        self,
        store: Store,
        redis_url: str,
        *,
        prefix: str = DEFAULT_PREFIX,
        block_ms: int = 2000,
        cancel_ttl_s: int = RETENTION_S,
        hub_capacity: int = 2000,
        max_connections: int = 100,
    ) -> None:
        self.store = store
        self.redis_url = redis_url
        self.keys = RedisKeys(prefix)
        self.block_ms = block_ms
        self.max_connections = max_connections
        self.cancel_ttl_s = cancel_ttl_s
        self.hub = EventHub(hub_capacity)
        self._client: aredis.Redis | None = None
        self._publisher: AsyncEventPublisher | None = None
        self.quiet_check_s = 5.0
        self._readers: dict[str, asyncio.Task[None]] = {}
        self._ready: dict[str, asyncio.Event] = {}
        self._pump_: _StreamPump | None = None
        self.reconcile_s = 1.0
        self.requeue_after_s = 3.0
        self._unfinished: set[str] = set()
        self._missing: dict[str, float] = {}
        self._finishing: dict[str, float] = {}
        self._warned_versions: set[str] = set()
        self._submit_lua: Any = None
        self._reconciler: asyncio.Task[None] | None = None
        self.requeued = 0
        self.redis_ok = False
        self.rescan_s = 30.0
        self._next_rescan = 0.0

    # -- lifecycle ------------------------------------------------------------------------------
    async def start(self) -> None:
        # a blocking pool: a burst of requests waits for a connection instead of failing; blocking
        # reads must end before the socket timeout (redis-py's default is 5 s)
        pool = aredis.BlockingConnectionPool.from_url(
            self.redis_url,
            decode_responses=True,
            socket_timeout=self.block_ms / 1000 + 5,
            max_connections=self.max_connections,
            timeout=30,
        )
        client = aredis.Redis.from_pool(pool)
        self._client = client
        self._submit_lua = client.register_script(SUBMIT_LUA)
        self._publisher = AsyncEventPublisher(client, self.store, self.keys)
        self._unfinished = {
            i.id for i in await asyncio.to_thread(self.store.list_jobs) if not i.status.finished
        }
        try:
            await self._reconcile(first=True)
        except (redis.ConnectionError, redis.TimeoutError) as exc:
            log.warning("Redis is not reachable yet (%s); jobs are refused with 503 until it is", exc)
        self._pump_ = _StreamPump(client, self.hub, self.keys, self.block_ms, self._append)
        self._pump_.start()
        self._reconciler = asyncio.create_task(self._reconcile_loop(), name="segue-reconcile")

    async def close(self) -> None:
        if self._reconciler is not None:
            # cancelled until it ends: a cancel that lands inside a Redis call can be swallowed
            # there (seen once: the loop went on and close() waited for ever)
            while not self._reconciler.done():
                self._reconciler.cancel()
                await asyncio.wait({self._reconciler}, timeout=1.0)
            self._reconciler = None
        readers = list(self._readers.values())
        for task in readers:
            task.cancel()
        for task in readers:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._readers.clear()
        if self._pump_ is not None:
            await self._pump_.stop()
            self._pump_ = None
        if self._client is not None:
            await self._client.aclose()
            self._client = None
            self._publisher = None

    def _redis(self) -> tuple[aredis.Redis, AsyncEventPublisher]:
        if self._client is None or self._publisher is None:
            raise RuntimeError("the Redis backend is not started")
        return self._client, self._publisher

    @property
    def _pump(self) -> _StreamPump:
        if self._pump_ is None:
            raise RuntimeError("the Redis backend is not started")
        return self._pump_

    # -- jobs -------------------------------------------------------------------------------------
    async def submit(self, info: JobInfo, kind: str, payload: dict[str, Any]) -> JobInfo:
        client, publisher = self._redis()
        self.store.check_id(info.id)  # NotFoundError for an invalid id
        try:
            if not await client.set(self.keys.job(info.id), info.model_dump_json(), nx=True):
                return await self.status(info.id)  # submitted before: nothing to do
            queued = await publisher.publish(info.id, EventType.queued, {})
            await self._enqueue(client, info.id, kind, payload, info.owner)
        except (redis.ConnectionError, redis.TimeoutError) as exc:
            with contextlib.suppress(redis.RedisError):
                await client.delete(
                    self.keys.job(info.id), self.keys.events(info.id), self.keys.event_seq(info.id)
                )
            raise BackendUnavailable(f"Redis is unreachable: {exc}") from None
        self._unfinished.add(info.id)
        if queued is not None:  # the history's first line, in the store at once (workers batch the rest)
            await asyncio.to_thread(archive_event, self.store, queued)
        return await self.status(info.id)

    async def _enqueue(
        self, client: aredis.Redis, job_id: str, kind: str, payload: dict[str, Any], owner: str | None
    ) -> None:
        """Queue a job on its principal's waiting list (:mod:`workers.redis_queue`), stamped with
        this API's version (:mod:`workers.version`)."""
        entry = queue_entry(job_id, kind, payload, owner, **stamp())
        keys = [principal_list(self.keys, owner), self.keys.queues, self.keys.bell]
        await self._submit_lua(keys=keys, args=[entry, "tail", BELL_MAX])

    # -- reconcile -----------------------------------------------------------------------------------
    async def _reconcile_loop(self) -> None:
        while True:
            await asyncio.sleep(self.reconcile_s)
            try:
                await self._reconcile()
            except (redis.ConnectionError, redis.TimeoutError) as exc:
                if self.redis_ok:
                    log.warning("Redis unreachable (%s); will re-queue what it loses once it is back", exc)
                self.redis_ok = False
            except Exception:  # a bug: keep reconciling
                log.exception("reconcile failed")

    async def _reconcile(self, first: bool = False) -> None:
        """Queue again the unfinished jobs Redis has forgotten (see the module docstring)."""
        client, _ = self._redis()
        await client.ping()
        try:
            await client.xgroup_create(self.keys.jobs, self.keys.group, id="0", mkstream=True)
        except redis.ResponseError as exc:
            if "BUSYGROUP" not in str(exc):
                raise
        if not self.redis_ok and not first:
            log.warning("Redis is reachable again; reconciling %d unfinished jobs", len(self._unfinished))
        self.redis_ok = True
        now = asyncio.get_running_loop().time()
        if now >= self._next_rescan:  # jobs other API processes submitted (if one of them died)
            self._next_rescan = now + self.rescan_s
            stored = await asyncio.to_thread(self.store.list_jobs)
            self._unfinished |= {i.id for i in stored if not i.status.finished}
        self._unfinished = await asyncio.to_thread(self._still_unfinished, set(self._unfinished))
        if not self._unfinished:
            return
        running: set[str] = set()
        async for key in client.scan_iter(match=self.keys.worker_pattern, count=500):
            with contextlib.suppress(ValueError, TypeError, AttributeError):
                job = json.loads(await client.get(key) or "{}").get("job")
                if job:
                    running.add(str(job))
        now = asyncio.get_running_loop().time()
        for job_id in sorted(self._unfinished):
            raw = await client.get(self.keys.job(job_id))
            if raw:
                self._missing.pop(job_id, None)
                if JobInfo.model_validate_json(raw).status.finished:
                    await self._settle_late(client, job_id, now)
                continue
            info = await asyncio.to_thread(self.store.job_info, job_id)
            if job_id in running:  # a worker still runs it: give Redis its status back
                await client.set(self.keys.job(job_id), info.model_dump_json(), nx=True)
                self._missing.pop(job_id, None)
                continue
            since = self._missing.setdefault(job_id, now)
            if now - since >= self.requeue_after_s:
                await self._requeue(client, info)
                self._missing.pop(job_id, None)

    async def _settle_late(self, client: aredis.Redis, job_id: str, now: float) -> None:
        """A job Redis says finished while the store does not, ``requeue_after_s`` after this was
        first seen: the process that published its terminal event died before writing the store's
        copies. Write them from Redis (settle, archive, record) as that process would have."""
        since = self._finishing.setdefault(job_id, now)
        if now - since < self.requeue_after_s:
            return
        self._finishing.pop(job_id, None)
        raw = await client.get(self.keys.job(job_id))
        entries = cast(Entries, await client.xrange(self.keys.events(job_id)))
        if not raw:
            return
        info = JobInfo.model_validate_json(raw)
        streamed = [decode_event(fields) for _, fields in entries]
        terminal = next((e for e in reversed(streamed) if e.type.terminal), None)
        if terminal is None:
            return  # the stream is gone too: the archive has what there is
        log.warning("job %s ended without its store records (its publisher died?); writing them", job_id)
        try:
            await asyncio.to_thread(_write_records, self.store, info, streamed, terminal)
        except OSError as exc:  # the store is away: the next round tries again
            log.warning("job %s: its store records cannot be written yet (%s)", job_id, exc)

    def _still_unfinished(self, jobs: set[str]) -> set[str]:
        out = set()
        for job_id in jobs:
            with contextlib.suppress(NotFoundError):
                if not self.store.job_info(job_id).status.finished:
                    out.add(job_id)
        return out

    async def _requeue(self, client: aredis.Redis, info: JobInfo) -> None:
        try:
            request = await asyncio.to_thread(self.store.job_request, info.id)
        except NotFoundError:
            return
        archived = await asyncio.to_thread(read_archive, self.store, info.id)
        floor = max(
            info.last_event,
            self.hub.log(info.id).last_id if self.hub.has(info.id) else 0,
            archived[-1].id if archived else 0,
        )
        if not await client.set(self.keys.job(info.id), info.model_dump_json(), nx=True):
            return  # another API process got there first
        # give the stream back the events this process knows (it followed the job) and the store's
        # batches hold, or at least the job's `queued` event, so readers find them in Redis again
        known = merge(self.hub.log(info.id).events if self.hub.has(info.id) else [], archived)
        if not known and floor >= 1:
            when = info.created_at.timestamp()
            known = [JobEvent(id=1, job=info.id, type=EventType.queued, time=when, data={})]
        if not await client.exists(self.keys.events(info.id)):
            for event in known:
                with contextlib.suppress(redis.ResponseError):  # an id already there
                    await client.xadd(
                        self.keys.events(info.id), {"event": event.model_dump_json()}, id=stream_id(event.id)
                    )
        await client.set(self.keys.event_seq(info.id), floor, nx=True)
        await self._enqueue(client, info.id, str(request["kind"]), dict(request["payload"]), info.owner)
        self.requeued += 1
        log.warning("job %s was lost by Redis (status %s); queued again", info.id, info.status.value)

    async def status(self, job_id: str) -> JobInfo:
        client, _ = self._redis()
        self.store.check_id(job_id)  # NotFoundError for an invalid id
        try:
            raw = await client.get(self.keys.job(job_id))
        except (redis.ConnectionError, redis.TimeoutError):
            raw = None  # Redis is away: the store's record (kept in step at every status change)
        if raw:
            return JobInfo.model_validate_json(raw)
        return await asyncio.to_thread(self.store.job_info, job_id)  # a file read: off the event loop

    async def cancel(self, job_id: str) -> JobInfo:
        client, publisher = self._redis()
        info = await self.status(job_id)
        if info.status.finished:
            return info
        try:
            return await self._cancel(client, publisher, info)
        except (redis.ConnectionError, redis.TimeoutError) as exc:
            raise BackendUnavailable(f"Redis is unreachable: {exc}") from None

    async def _cancel(self, client: aredis.Redis, publisher: AsyncEventPublisher, info: JobInfo) -> JobInfo:
        job_id = info.id
        await client.set(self.keys.cancel(job_id), "1", ex=self.cancel_ttl_s)
        if info.status == JobStatus.queued:
            # no worker has it yet: end it now; a worker receiving it later finds the terminal marker
            # (attempt 0: refused once a run started; that run sees the cancel flag and ends itself)
            floor = self.hub.log(job_id).last_id if self.hub.has(job_id) else 0
            with contextlib.suppress(StaleAttempt):
                await publisher.publish(job_id, EventType.cancelled, {"result": info.result}, floor=floor)
        return await self.status(job_id)

    async def delete(self, job_id: str) -> None:
        client, _ = self._redis()
        info = await self.status(job_id)
        if not info.status.finished:
            raise JobNotFinished(f"job {job_id} is {info.status.value}")
        # the publisher of the terminal event writes the store's archive, then its record, just
        # after Redis says finished: delete once both are written, or they would bring the job back
        for _ in range(100):
            archived = await asyncio.to_thread(self.store.events, job_id)
            stored = await asyncio.to_thread(self.store.job_info, job_id)
            if (
                archived
                and stored.status.finished
                and JobEvent.model_validate_json(archived[-1]).type.terminal
            ):
                break
            await asyncio.sleep(0.05)
        else:
            stored = await asyncio.to_thread(self.store.job_info, job_id)
            if not stored.status.finished:  # no archive: wait for the store's record at least
                raise JobNotFinished(f"job {job_id} is finishing (its record is being written)")
        reader = self._readers.pop(job_id, None)
        if reader is not None:
            reader.cancel()
        keys = self.keys
        try:
            # the terminal marker stays (until it expires): a stale attempt still cannot publish
            await client.delete(
                keys.job(job_id), keys.events(job_id), keys.event_seq(job_id), keys.cancel(job_id)
            )
        except (redis.ConnectionError, redis.TimeoutError) as exc:
            raise BackendUnavailable(f"Redis is unreachable: {exc}") from None
        self._unfinished.discard(job_id)
        self.hub.forget(job_id)
        await asyncio.to_thread(self.store.delete_job, job_id)

    # -- events ------------------------------------------------------------------------------------
    async def backlog(self, job_id: str, after: int = 0) -> list[JobEvent]:
        info = await self.status(job_id)  # NotFoundError for unknown jobs
        job_log = self.hub.log(job_id)
        if not job_log.terminal:
            await self._ensure_reader(job_id).wait()  # set once the reader caught up (XRANGE, archive)
            await self._refresh(job_id, info.status.finished)
        return [e for e in job_log.events if e.id > after]

    async def _refresh(self, job_id: str, finished: bool) -> None:
        """Bring a followed job's log up to now: an event committed before this call is in it
        (the reader's pump may not have delivered it yet), so a client that read the status
        ``done`` finds the terminal event. A job Redis forgot that ended: its archive."""
        client, _ = self._redis()
        with contextlib.suppress(redis.ConnectionError, redis.TimeoutError):
            await self._catch_up(client, job_id)
        if finished and not self.hub.log(job_id).terminal:
            await self._read_archive(job_id)

    async def events(self, job_id: str, after: int = 0) -> AsyncIterator[JobEvent]:
        await self.status(job_id)  # NotFoundError for unknown jobs
        job_log = self.hub.log(job_id)
        if not job_log.terminal:
            await self._ensure_reader(job_id).wait()
            reader = self._readers.get(job_id)
            if not job_log.terminal and (reader is None or reader.done()):
                # the reader has nothing more to give (the job's events are gone): what we have
                for event in [e for e in job_log.events if e.id > after]:
                    yield event
                return
        async for event in self.hub.follow(job_id, after):
            yield event

    def _ensure_reader(self, job_id: str) -> asyncio.Event:
        """The job's reader task (started if needed); returns an event set once it caught up."""
        task = self._readers.get(job_id)
        if task is not None and not task.done():
            return self._ready[job_id]
        ready = self._ready[job_id] = asyncio.Event()
        self.hub.log(job_id).exhausted = False  # a new source: followers wait for it again
        task = asyncio.create_task(self._read_job(job_id, ready), name=f"segue-events-{job_id}")
        self._readers[job_id] = task
        task.add_done_callback(functools.partial(self._reader_done, job_id))
        return ready

    def _reader_done(self, job_id: str, task: asyncio.Task[None]) -> None:
        if self._readers.get(job_id) is task:
            del self._readers[job_id]
            self._ready.pop(job_id, None)
        if not task.cancelled() and task.exception() is not None:
            log.error("event reader of job %s failed", job_id, exc_info=task.exception())

    async def _catch_up(self, client: aredis.Redis, job_id: str) -> int:
        """Append every event in Redis after the hub's last one (and, where Redis lacks earlier
        ones, the store's archive of them first); returns how many."""
        job_log = self.hub.log(job_id)
        added = 0
        while True:
            entries = cast(
                Entries,
                await client.xrange(self.keys.events(job_id), min=stream_id(job_log.last_id + 1), count=1000),
            )
            for _, fields in entries:
                added += await self._append(decode_event(fields))
            if len(entries) < 1000:
                return added

    async def _append(self, event: JobEvent) -> bool:
        """Add an event to the hub, after the events before it that Redis lost (a restart without
        persistence, a flush) and the store's archive holds: a log never has a gap it could fill."""
        job_log = self.hub.log(event.job)
        if event.id > job_log.last_id + 1:
            for archived in await asyncio.to_thread(read_archive, self.store, event.job):
                if job_log.last_id < archived.id < event.id:
                    await self.hub.append(archived)
        return await self.hub.append(event)

    async def _read_archive(self, job_id: str) -> None:
        for event in await asyncio.to_thread(read_archive, self.store, job_id):
            await self.hub.append(event)

    async def _read_job(self, job_id: str, ready: asyncio.Event) -> None:
        """Catch up with XRANGE, then follow through the pump until the terminal event."""
        client, _ = self._redis()
        job_log = self.hub.log(job_id)
        caught_up, followed, backoff = False, False, 0.1
        try:
            while not job_log.terminal:
                try:
                    if not caught_up:
                        await self._catch_up(client, job_id)
                        if job_log.last_id == 0 and not await client.exists(self.keys.events(job_id)):
                            await self._read_archive(job_id)  # Redis forgot the job (retention, flush)
                        caught_up = True
                        ready.set()
                        if not followed and not job_log.terminal:
                            await self._pump.add(job_id)
                            followed = True
                        continue
                    last = job_log.last_id
                    try:
                        await asyncio.wait_for(_changed(job_log, last), self.quiet_check_s)
                    except TimeoutError:
                        # quiet: stop if the job ended without its terminal event reaching us
                        if (await self.status(job_id)).status.finished:
                            await self._catch_up(client, job_id)
                            if not job_log.terminal:
                                await self._read_archive(job_id)
                            return
                except (redis.ConnectionError, redis.TimeoutError) as exc:
                    log.warning("event reader of job %s: %s; retrying in %.1f s", job_id, exc, backoff)
                    await asyncio.sleep(backoff)
                    backoff, caught_up = min(backoff * 2, 5.0), False
        finally:
            if self._pump_ is not None:
                self._pump_.remove(job_id)
            ready.set()
            if not job_log.terminal:  # ended without the terminal event: release the followers
                await self.hub.set_exhausted(job_id)

    # -- health ------------------------------------------------------------------------------------
    async def _worker_versions(self, client: aredis.Redis, names: list[str]) -> dict[str, str]:
        """Each live worker's version as its heartbeat announces it; a worker of another version
        than this API is logged (it refuses this API's jobs)."""
        out: dict[str, str] = {}
        mine = describe(stamp())
        for name in names:
            with contextlib.suppress(ValueError, TypeError, AttributeError):
                beat = json.loads(await client.get(self.keys.worker(name)) or "{}")
                out[name] = describe({"version": beat.get("version"), "format": beat.get("format")})
        for name, theirs in out.items():
            if theirs != mine and name not in self._warned_versions:
                self._warned_versions.add(name)
                log.error("worker %s is %s, this API %s: it refuses this API's jobs", name, theirs, mine)
        return out

    async def health(self) -> dict[str, Any]:
        client, _ = self._redis()
        facts: dict[str, Any] = {"backend": "redis"}
        try:
            pattern, cut = self.keys.worker_pattern, len(self.keys.worker(""))
            names = sorted([key[cut:] async for key in client.scan_iter(match=pattern, count=500)])
            pending = 0
            with contextlib.suppress(redis.ResponseError):  # no stream yet
                for group in await client.xinfo_groups(self.keys.jobs):
                    if group["name"] == self.keys.group:
                        pending = int(group["pending"])
            length = int(await client.xlen(self.keys.jobs))  # finished entries are deleted
            lists = cast(list[str], await client.zrange(self.keys.queues, 0, -1))
            waiting = 0
            if lists:
                async with client.pipeline(transaction=False) as pipe:
                    for name in lists:
                        pipe.llen(name)
                    waiting = sum(int(n) for n in await pipe.execute())
            versions = await self._worker_versions(client, names)
            facts.update(
                redis="ok",
                workers=len(names),
                worker_names=names,
                worker_versions=versions,
                queued=waiting + max(length - pending, 0),
                principals_waiting=len(lists),
                pending=pending,
                dead_letters=int(await client.xlen(self.keys.dead)),
                followed_jobs=len(self._readers),
                unfinished_jobs=len(self._unfinished),
                requeued=self.requeued,
            )
        except redis.RedisError as exc:
            facts.update(redis="unreachable", error=f"Redis is unreachable: {exc}")
        return facts


def _write_records(store: Store, info: JobInfo, events: list[JobEvent], terminal: JobEvent) -> None:
    """A finished job's store copies, in the order its publisher writes them."""
    settle(store, info, terminal)
    archive_events(store, info.id, events)
    put_job_record(store, info)


async def _changed(job_log: JobLog, last: int) -> None:
    """Wait until a job's log has an event after ``last`` (or ended)."""
    async with job_log.cond:
        await job_log.cond.wait_for(lambda: job_log.last_id > last or job_log.terminal)


class _StreamPump:
    """One blocking ``XREAD`` for every job an API process follows: one connection, not one per job.

    Each round reads all followed streams from the hub's last id of each job, plus this process's
    wake stream: adding a job ``XADD``\\ s to it, so a read blocked on the old set returns at once.
    """

    def __init__(
        self,
        client: aredis.Redis,
        hub: EventHub,
        keys: RedisKeys,
        block_ms: int,
        append: Callable[[JobEvent], Awaitable[bool]] | None = None,
    ) -> None:
        self.client, self.hub, self.keys, self.block_ms = client, hub, keys, block_ms
        self.append = append or hub.append
        """Adds an event to the hub (the backend's fills a gap from the store's archive first)."""
        self.jobs: set[str] = set()
        self._wake_key = keys.api_wake(uuid.uuid4().hex)
        self._wake_cursor = "0-0"
        self._changed = asyncio.Event()
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        self._task = asyncio.create_task(self._run(), name="segue-event-pump")

    async def stop(self) -> None:
        if self._task is not None:
            # cancelled until it ends: redis-py can swallow a cancel that lands inside a blocking
            # read, and the loop would go on (close() then waited for ever)
            while not self._task.done():
                self._task.cancel()
                await asyncio.wait({self._task}, timeout=1.0)
            self._task = None
        with contextlib.suppress(redis.RedisError):
            await self.client.delete(self._wake_key)

    async def add(self, job_id: str) -> None:
        self.jobs.add(job_id)
        self._changed.set()
        async with self.client.pipeline(transaction=False) as pipe:
            pipe.xadd(self._wake_key, {"wake": "1"}, maxlen=1, approximate=False)
            pipe.expire(self._wake_key, 3600)
            await pipe.execute()

    def remove(self, job_id: str) -> None:
        self.jobs.discard(job_id)

    async def _run(self) -> None:
        backoff = 0.1
        while True:
            try:
                if not self.jobs:
                    self._changed.clear()
                    await self._changed.wait()
                    continue
                streams = {self.keys.events(j): stream_id(self.hub.log(j).last_id) for j in self.jobs}
                streams[self._wake_key] = self._wake_cursor
                response = cast(
                    list[tuple[str, Entries]] | None,
                    await self.client.xread(streams, count=500, block=self.block_ms),  # type: ignore[arg-type]
                )
                backoff = 0.1
                for key, entries in response or []:
                    if key == self._wake_key:
                        self._wake_cursor = entries[-1][0]
                        continue
                    for _, fields in entries:
                        await self.append(decode_event(fields))
                self.jobs = {j for j in self.jobs if not self.hub.log(j).terminal}
            except (redis.ConnectionError, redis.TimeoutError) as exc:
                log.warning("event pump: %s; retrying in %.1f s", exc, backoff)
                await asyncio.sleep(backoff)
                backoff = min(backoff * 2, 5.0)
            except Exception:  # a bug: keep following the other jobs
                log.exception("event pump failed; restarting it")
                await asyncio.sleep(1.0)


__all__ = ["NotFoundError", "RedisBackend"]
