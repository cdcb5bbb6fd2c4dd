"""Publishing job events through Redis: one protocol for the API (asyncio) and the workers (threads).

Publishing one event is one optimistic transaction (``WATCH`` the job's counter, status, terminal
marker and attempt; ``MULTI``/``EXEC``; retried if another process published in between):

1. if the terminal marker ``segue:job:<job>:terminal`` exists, the event is dropped: nothing follows
   a terminal event, and a job's terminal event is published exactly once;
2. the fence (:mod:`workers.fencing`): a run publishes only while ``segue:job:<job>:attempt`` holds
   its attempt, else :class:`~workers.fencing.StaleAttempt` is raised and nothing is written (the
   key is watched, so a run taking the job between the check and ``EXEC`` makes the transaction
   fail and the check run again); the event carries the attempt;
3. the id is ``INCR segue:events:<job>:seq``: contiguous 1, 2, 3... whichever process publishes (a
   lost counter restarts after the stream's last entry or the last id the publisher saw, so a flushed
   Redis never reuses ids clients already have);
4. a terminal event sets the marker (``SET NX``) in the same transaction;
5. ``XADD segue:events:<job> MAXLEN ~ 10000 <id>-0 event <JobEvent JSON>``: the entry id *is* the
   event id, so resuming after event ``N`` is ``XRANGE N+1-0 +`` then ``XREAD`` from ``N-0``;
6. the job's JobInfo, folded with :func:`workers.execute.apply_event`, is written in the same
   transaction, so a client that sees an event also sees the status after it;
7. once terminal, the stream, counter, marker, attempt and status expire after the retention period.

After the transaction the JobInfo is also written to the store's ``info.json`` when the status
changes (``queued``, ``started``, the terminal event; not for every progress or solution event, which
would cost a file write each; never backwards, :func:`workers.records.put_job_record`). A worker's
publisher copies every event to the store in batches as it goes (:mod:`workers.event_archive`), so
a Redis that loses its memory loses no history. The process that publishes the terminal event
settles a build's database record and a small job's staged upload (:func:`workers.records.settle`),
writes the job's whole archive to the store's ``events.jsonl`` (the file the embedded backend
writes: the stream merged with the batches), so finished jobs replay after Redis forgot them, and
only then the job's finished ``info.json``.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass
from typing import Any, Generic, TypeVar, cast

import redis
import redis.asyncio as aredis

from schemas import EventType, JobEvent, JobInfo

from .event_archive import BatchArchiver, archive_events, merge
from .execute import apply_event
from .fencing import StaleAttempt
from .records import put_job_record, settle
from .redis_keys import EVENTS_MAXLEN, RedisKeys
from .store import NotFoundError, Store

log = logging.getLogger("segue.redis")

Client = TypeVar("Client", redis.Redis, aredis.Redis)
Entries = list[tuple[str, dict[str, str]]]
"""Stream entries as a ``decode_responses=True`` client returns them: (entry id, fields)."""

DISK_STATUS_EVENTS = frozenset(
    {EventType.queued, EventType.started, EventType.done, EventType.failed, EventType.cancelled}
)
"""Events after which the store's ``info.json`` is rewritten (status changes)."""

RETENTION_S = 7 * 24 * 3600
"""How long Redis keeps a finished job's events and status (the store keeps them for good)."""


def stream_id(event_id: int) -> str:
    """The stream entry id of an event."""
    return f"{event_id}-0"


def decode_event(fields: dict[str, str]) -> JobEvent:
    """A JobEvent from a stream entry's fields."""
    return JobEvent.model_validate_json(fields["event"])


def fold_info(current: JobInfo, event: JobEvent) -> JobInfo | None:
    """The JobInfo after ``event``, or None when the event must not change it (stale or late)."""
    if current.status.finished or current.last_event >= event.id:
        return None
    return apply_event(current, event.type, event.data, event.id)


@dataclass(slots=True)
class _Plan:
    event: JobEvent
    info: JobInfo | None
    recovered: bool  # the counter was lost: SET it instead of INCR
    restore_attempt: bool = False  # the attempt key was lost: SET it back to the event's attempt


def fenced_attempt(job_id: str, attempt: int | None, current: str | None) -> tuple[int, bool]:
    """The attempt an event carries and whether the attempt key must be restored, given the key's
    ``current`` value; raises :class:`StaleAttempt` when the publisher's ``attempt`` is not the
    job's. ``attempt``: a run's token; 0 only before any run started; None for whichever run holds
    the job (a dead letter)."""
    held = int(current) if current is not None else None
    if attempt is None:
        return held or 0, False
    if attempt == 0:
        if held:
            raise StaleAttempt(job_id, 0, held)
        return 0, False
    if held is None:
        return attempt, True  # Redis lost the key: a run still publishing puts it back
    if held != attempt:
        raise StaleAttempt(job_id, attempt, held)
    return attempt, False


def _plan(
    store: Store,
    job_id: str,
    type_: EventType,
    data: dict[str, Any],
    when: float,
    seq: str | None,
    job: str | None,
    last_entry: str | None,
    floor: int,
    attempt: int = 0,
) -> _Plan:
    if seq is None:
        event_id = max(int(last_entry.split("-")[0]) if last_entry else 0, floor) + 1
    else:
        event_id = int(seq) + 1
    event = JobEvent(id=event_id, job=job_id, type=type_, time=when, data=data, attempt=attempt)
    try:
        current = JobInfo.model_validate_json(job) if job else store.job_info(job_id)
    except NotFoundError:
        log.warning("job %s has no stored info; its status is not updated", job_id)
        current = None
    return _Plan(event, None if current is None else fold_info(current, event), seq is None)


def _queue(pipe: Any, keys: RedisKeys, plan: _Plan, maxlen: int, retention_s: int) -> None:
    """Queue the writes of one event in a MULTI block (sync or asyncio pipeline)."""
    event, job_id = plan.event, plan.event.job
    if plan.restore_attempt:
        pipe.set(keys.attempt(job_id), event.attempt)
    if plan.recovered:
        pipe.set(keys.event_seq(job_id), event.id)
    else:
        pipe.incr(keys.event_seq(job_id))
    if event.type.terminal:
        pipe.set(keys.terminal(job_id), event.id, nx=True)
    pipe.xadd(
        keys.events(job_id),
        {"event": event.model_dump_json()},
        id=stream_id(event.id),
        maxlen=maxlen,
        approximate=True,
    )
    if plan.info is not None:
        pipe.set(
            keys.job(job_id),
            plan.info.model_dump_json(),
            ex=retention_s if plan.info.status.finished else None,
        )
    if event.type.terminal:
        for key in (keys.event_seq(job_id), keys.events(job_id), keys.terminal(job_id), keys.attempt(job_id)):
            pipe.expire(key, retention_s)


class _Publisher(Generic[Client]):
    """What both publishers share: the keys a publish watches, and the store written after it."""

    def __init__(
        self,
        client: Client,
        store: Store,
        keys: RedisKeys,
        maxlen: int = EVENTS_MAXLEN,
        retention_s: int = RETENTION_S,
    ) -> None:
        self.client: Client = client
        self.store, self.keys = store, keys
        self.maxlen, self.retention_s = maxlen, retention_s

    def _watched(self, job_id: str) -> list[str]:
        """The job's event counter, status, terminal marker and attempt (a publish is optimistic
        on them)."""
        keys = self.keys
        return [keys.event_seq(job_id), keys.job(job_id), keys.terminal(job_id), keys.attempt(job_id)]

    def _recorded(
        self, plan: _Plan, entries: Entries | None, unwritten: list[JobEvent] | None = None
    ) -> None:
        """After the transaction: the store's copies. A terminal event (``entries``: the job's
        stream, read after it) settles the job's database or staged upload, writes its whole
        archive (the stream merged with the batches already stored and ``unwritten``, so what
        Redis lost is kept), then its finished record: a reader that sees the store say finished
        finds the terminal event archived, and the API's delete waits for both. Other events
        rewrite the record when the status changes."""
        if entries is None:
            if plan.info is not None and plan.event.type in DISK_STATUS_EVENTS:
                put_job_record(self.store, plan.info)
            return
        if plan.info is not None:
            settle(self.store, plan.info, plan.event)
        streamed = [decode_event(fields) for _, fields in entries]
        archive_events(self.store, plan.event.job, merge([plan.event], streamed, unwritten or []))
        if plan.info is not None:
            put_job_record(self.store, plan.info)


class EventPublisher(_Publisher[redis.Redis]):
    """Publishes events from a worker (synchronous client, ``decode_responses=True``)."""

    def __init__(
        self,
        client: redis.Redis,
        store: Store,
        keys: RedisKeys,
        maxlen: int = EVENTS_MAXLEN,
        retention_s: int = RETENTION_S,
        archiver: BatchArchiver | None = None,
    ) -> None:
        super().__init__(client, store, keys, maxlen, retention_s)
        self._last: dict[str, int] = {}  # last event id published per running job (survives a flush)
        self.archiver = archiver
        """Copies each published event to the store in batches (None: only the whole archive at
        the end)."""

    def publish(
        self,
        job_id: str,
        type_: EventType,
        data: dict[str, Any],
        when: float | None = None,
        attempt: int | None = None,
    ) -> JobEvent | None:
        """Publish one event of run ``attempt`` (see :func:`fenced_attempt`); returns it, or None
        when dropped (the job already has its terminal event). Raises
        :class:`~workers.fencing.StaleAttempt` when another run holds the job."""
        keys, when = self.keys, when or time.time()
        watched = self._watched(job_id)
        with self.client.pipeline() as pipe:
            while True:
                try:
                    pipe.watch(*watched)  # type: ignore[no-untyped-call]
                    seq, job, terminal, current = cast(list[str | None], pipe.mget(watched))
                    if terminal is not None:
                        self._last.pop(job_id, None)
                        log.info("job %s: %s dropped, the job already ended", job_id, type_.value)
                        return None
                    stamp, restore = fenced_attempt(job_id, attempt, current)
                    last = None
                    if seq is None:
                        tail = cast(list[tuple[str, Any]], pipe.xrevrange(keys.events(job_id), count=1))
                        last = tail[0][0] if tail else None
                    floor = self._last.get(job_id, 0)
                    plan = _plan(self.store, job_id, type_, data, when, seq, job, last, floor, stamp)
                    plan.restore_attempt = restore
                    pipe.multi()
                    _queue(pipe, keys, plan, self.maxlen, self.retention_s)
                    pipe.execute()
                    break
                except redis.WatchError:
                    continue
        if type_.terminal:
            unwritten = self.archiver.take(job_id) if self.archiver is not None else []
            entries = cast(Entries, self.client.xrange(keys.events(job_id)))
            self._recorded(plan, entries, unwritten)
            self._last.pop(job_id, None)
        else:
            if self.archiver is not None:
                self.archiver.add(plan.event)
            self._recorded(plan, None)
            self._last[job_id] = plan.event.id
        return plan.event

    def forget(self, job_id: str) -> None:
        """Drop what this publisher remembers of a job (its run in this process is over)."""
        self._last.pop(job_id, None)


class AsyncEventPublisher(_Publisher[aredis.Redis]):
    """Publishes events from the API process (``redis.asyncio`` client, ``decode_responses=True``)."""

    async def publish(
        self,
        job_id: str,
        type_: EventType,
        data: dict[str, Any],
        when: float | None = None,
        floor: int = 0,
        attempt: int | None = 0,
    ) -> JobEvent | None:
        """Publish one event; returns it, or None when dropped (the job already has its terminal event).

        ``floor``: the last event id this process knows of (used only if Redis lost the counter).
        ``attempt``: 0 (the API's events: ``queued``, a cancel while queued) raises
        :class:`~workers.fencing.StaleAttempt` once a run started.
        """
        keys, when = self.keys, when or time.time()
        watched = self._watched(job_id)
        async with self.client.pipeline() as pipe:
            while True:
                try:
                    await pipe.watch(*watched)
                    seq, job, terminal, current = cast(list[str | None], await pipe.mget(watched))
                    if terminal is not None:
                        return None
                    stamp, restore = fenced_attempt(job_id, attempt, current)
                    last = None
                    if seq is None:
                        tail = cast(Entries, await pipe.xrevrange(keys.events(job_id), count=1))
                        last = tail[0][0] if tail else None
                    plan = _plan(self.store, job_id, type_, data, when, seq, job, last, floor, stamp)
                    plan.restore_attempt = restore
                    pipe.multi()  # type: ignore[no-untyped-call]
                    _queue(pipe, keys, plan, self.maxlen, self.retention_s)
                    await pipe.execute()
                    break
                except redis.WatchError:
                    continue
        if type_.terminal:
            entries = cast(Entries, await self.client.xrange(keys.events(job_id)))
            await asyncio.to_thread(self._recorded, plan, entries)
        else:
            await asyncio.to_thread(self._recorded, plan, None)
        return plan.event
