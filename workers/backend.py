"""The job backend protocol and the in-process event hub shared by both backends.

A backend runs jobs somewhere (a local process pool, or ``segue worker`` processes through Redis)
and feeds their events into an :class:`EventHub` in the API process; WebSockets and HTTP handlers
read from the hub. Event ids increase by one per job, starting at 1 (the ``queued`` event), so a
client resumes with ``after=<last id it saw>``.
"""

from __future__ import annotations

import asyncio
import time
from collections import OrderedDict
from collections.abc import AsyncIterator, Callable
from typing import Any, Protocol

from schemas import EventType, JobEvent, JobInfo


class BackendUnavailable(RuntimeError):
    """The backend cannot take a job now (Redis unreachable, no worker process can start); the
    API answers 503 and keeps no record of the job."""


class JobNotFinished(RuntimeError):
    """A job cannot be deleted while it is queued or running (cancel it first)."""


class JobBackend(Protocol):
    """Where jobs run. All methods are called from the API's event loop."""

    hub: EventHub

    async def start(self) -> None:
        """Start workers/readers (called once at API start-up)."""

    async def close(self) -> None:
        """Stop accepting jobs and release workers."""

    async def submit(self, info: JobInfo, kind: str, payload: dict[str, Any]) -> JobInfo:
        """Queue a job (its JobInfo already stored, status queued); emits the ``queued`` event."""

    async def status(self, job_id: str) -> JobInfo:
        """The job's current status (raises ``NotFoundError``)."""

    async def cancel(self, job_id: str) -> JobInfo:
        """Ask a job to stop; it ends with ``cancelled`` and its best result so far."""

    def events(self, job_id: str, after: int = 0) -> AsyncIterator[JobEvent]:
        """The job's events with id > ``after``, waiting for new ones, ending after the terminal one."""

    async def backlog(self, job_id: str, after: int = 0) -> list[JobEvent]:
        """The job's events with id > ``after`` recorded so far, loaded from wherever they are kept
        (the store's archive, Redis) when this process has not got them yet; never waits for new
        ones. How long the loading takes never changes the answer (``GET .../events``)."""

    async def delete(self, job_id: str) -> None:
        """Remove a *finished* job everywhere (store, event log, Redis keys); raises
        :class:`JobNotFinished` while it is queued or running, ``NotFoundError`` when unknown."""

    async def health(self) -> dict[str, Any]:
        """Backend facts for /healthz and /metrics (workers alive, queue depth...)."""


class JobLog:
    """The events of one job in arrival order, with waiters for new ones."""

    __slots__ = ("cond", "events", "exhausted", "followers", "terminal")

    def __init__(self) -> None:
        self.events: list[JobEvent] = []
        self.cond = asyncio.Condition()
        self.terminal = False
        self.exhausted = False
        """The source of the events ended without a terminal event (the job's events are lost):
        followers get what there is instead of waiting for ever."""
        self.followers = 0

    @property
    def last_id(self) -> int:
        return self.events[-1].id if self.events else 0


class EventHub:
    """Per-job event logs in the API process, fanned out to any number of readers.

    Keeps the logs of the ``capacity`` most recently touched jobs; older ones are reloaded by the
    backend (from disk or Redis) when a client asks for them.
    """

    def __init__(self, capacity: int = 2000) -> None:
        self.capacity = capacity
        self._logs: OrderedDict[str, JobLog] = OrderedDict()
        self._listeners: list[Callable[[JobEvent], None]] = []

    def log(self, job_id: str) -> JobLog:
        log = self._logs.get(job_id)
        if log is None:
            log = self._logs[job_id] = JobLog()
            self._evict()
        self._logs.move_to_end(job_id)
        return log

    def _evict(self) -> None:
        """Forget the least recently used *finished, unfollowed* logs beyond capacity (a log that
        is still running or being read is never dropped)."""
        excess = len(self._logs) - self.capacity
        if excess <= 0:
            return
        for job_id in [j for j, lg in self._logs.items() if lg.terminal and lg.followers == 0][:excess]:
            del self._logs[job_id]

    def add_listener(self, listener: Callable[[JobEvent], None]) -> None:
        """Call ``listener(event)`` for every event appended (metrics, logging)."""
        self._listeners.append(listener)

    def has(self, job_id: str) -> bool:
        return job_id in self._logs

    def forget(self, job_id: str) -> None:
        """Drop a (deleted) job's log; readers that hold it finish with what it has."""
        self._logs.pop(job_id, None)

    async def append(self, event: JobEvent) -> bool:
        """Add an event (ignored when its id is not the next one: duplicates from a replay)."""
        log = self.log(event.job)
        if event.id <= log.last_id:
            return False
        async with log.cond:
            log.events.append(event)
            if event.type.terminal:
                log.terminal = True
            log.cond.notify_all()
        for listener in self._listeners:
            listener(event)
        return True

    def make_event(
        self, job_id: str, type_: EventType, data: dict[str, Any], when: float | None = None, attempt: int = 0
    ) -> JobEvent:
        """The next event of a job (id = last id + 1), published by run ``attempt``."""
        return JobEvent(
            id=self.log(job_id).last_id + 1,
            job=job_id,
            type=type_,
            time=when or time.time(),
            data=data,
            attempt=attempt,
        )

    async def set_exhausted(self, job_id: str, exhausted: bool = True) -> None:
        """Say that no more events of a job will arrive (or, ``False``, that a new source started);
        followers waiting for new events return once they have what there is."""
        log = self.log(job_id)
        async with log.cond:
            log.exhausted = exhausted
            log.cond.notify_all()

    async def follow(self, job_id: str, after: int = 0) -> AsyncIterator[JobEvent]:
        """Events with id > ``after``, waiting for new ones, until the terminal event."""
        log = self.log(job_id)
        log.followers += 1
        try:
            async for event in self._follow(log, after):
                yield event
        finally:
            log.followers -= 1

    async def _follow(self, log: JobLog, after: int) -> AsyncIterator[JobEvent]:
        cursor = after
        while True:
            async with log.cond:
                while log.last_id <= cursor and not log.terminal and not log.exhausted:
                    await log.cond.wait()
                pending = log.events[max(cursor - log.events[0].id + 1, 0) :] if log.last_id > cursor else []
            for event in pending:
                cursor = event.id
                yield event
                if event.type.terminal:
                    return
            if (log.terminal or log.exhausted) and cursor >= log.last_id:
                return
