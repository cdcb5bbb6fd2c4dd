"""A job's events copied to the store as they are published: the history that survives Redis.

Redis holds a running job's events in its stream. A Redis restarted without persistence (or
flushed) loses them, though the job goes on (its worker keeps publishing from the next id), so the
store keeps a copy as the events happen, not only at the end:

- **batches** (:class:`BatchArchiver`, in every worker): each event a worker publishes is buffered
  per job and written to the store as one object per batch (:meth:`Store.put_event_batch`,
  ``jobs/<id>/events/<first id>.jsonl``) once the oldest buffered event is ``flush_s`` old, by a
  thread of its own, so publishing never waits on the store; the API writes a job's ``queued``
  event as its first batch at submission (:func:`archive_event`);
- **the whole archive**: whoever publishes a job's terminal event writes ``events.jsonl``
  (:func:`archive_events`): the events Redis still has, merged with the batches (whatever Redis
  lost) and the ones not yet written, then removes the batches;
- **readers** (:func:`read_archive`) merge ``events.jsonl`` and the batches by event id; the API
  fills any gap in what Redis gives it from there (:mod:`workers.redis_backend`).

A batch is lost only if its worker dies before writing it *and* Redis loses the stream: within
``flush_s`` of each other.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Iterable

from schemas import JobEvent

from .store import NotFoundError, Store

log = logging.getLogger("segue.events.archive")

MAX_PENDING = 10_000
"""Most events kept per job while the store cannot take them (the oldest are dropped, logged)."""


def read_archive(store: Store, job_id: str) -> list[JobEvent]:
    """The events the store holds for a job (its ``events.jsonl`` and its batches), by id; empty
    when there are none."""
    try:
        lines = store.events(job_id) + store.event_batches(job_id)
    except NotFoundError:
        return []
    by_id: dict[int, JobEvent] = {}
    for line in lines:
        event = JobEvent.model_validate(json.loads(line))
        by_id.setdefault(event.id, event)
    return [by_id[i] for i in sorted(by_id)]


def merge(*sources: Iterable[JobEvent]) -> list[JobEvent]:
    """The events of several sources (Redis, the archive, unwritten batches) once each, by id (the
    first source wins a tie: the same id is the same event, fenced)."""
    by_id: dict[int, JobEvent] = {}
    for source in sources:
        for event in source:
            by_id.setdefault(event.id, event)
    return [by_id[i] for i in sorted(by_id)]


def archive_events(store: Store, job_id: str, events: Iterable[JobEvent]) -> None:
    """Write a finished job's whole archive (``events.jsonl``): ``events`` merged with what the
    store already holds (read only when ``events`` are not every id from 1 on: something was
    lost), then remove its batches. A store failure is logged: the batches stay and readers merge
    them."""
    events = merge(events)
    whole = [e.id for e in events] == list(range(1, len(events) + 1))
    try:
        merged = events if whole else merge(events, read_archive(store, job_id))
        store.put_events(job_id, [e.model_dump_json() for e in merged])
        store.delete_event_batches(job_id)
    except (OSError, NotFoundError):
        log.exception("could not archive the events of job %s", job_id)


def archive_event(store: Store, event: JobEvent) -> None:
    """Write one event as a batch of its own at once (the API's ``queued``)."""
    try:
        store.put_event_batch(event.job, event.id, [event.model_dump_json()])
    except (OSError, NotFoundError, ValueError) as exc:
        log.warning("job %s: event %d not archived yet (%s)", event.job, event.id, exc)


class BatchArchiver:
    """Buffers the events a process publishes and writes them to the store in batches (see the
    module docstring). ``add`` never touches the store; :meth:`run` (a thread) writes the batches
    due; :meth:`take` hands a finishing job's unwritten events to its terminal publisher."""

    def __init__(self, store: Store, flush_s: float = 1.0) -> None:
        self.store, self.flush_s = store, flush_s
        self._cond = threading.Condition()
        self._pending: dict[str, list[JobEvent]] = {}
        self._since: dict[str, float] = {}
        self._writing: set[str] = set()
        self.batches = 0

    def add(self, event: JobEvent) -> None:
        """Buffer one published event of a running job."""
        with self._cond:
            pending = self._pending.setdefault(event.job, [])
            pending.append(event)
            self._since.setdefault(event.job, time.monotonic())
            if len(pending) > MAX_PENDING:
                del pending[: len(pending) - MAX_PENDING]
                log.warning("job %s: the store took no events for a while; dropping the oldest", event.job)

    def take(self, job_id: str) -> list[JobEvent]:
        """The job's events not written yet, no longer buffered (its whole archive is about to be
        written); waits while a batch of the job is being written."""
        with self._cond:
            while job_id in self._writing:
                self._cond.wait()
            self._since.pop(job_id, None)
            return self._pending.pop(job_id, [])

    def flush(self, due_only: bool = True) -> int:
        """Write the batches due (every one with ``due_only`` False); how many were written."""
        now = time.monotonic()
        with self._cond:
            jobs = [j for j, t in self._since.items() if not due_only or now - t >= self.flush_s]
            work = {}
            for job_id in jobs:
                self._since.pop(job_id, None)
                work[job_id] = self._pending.pop(job_id, [])
                self._writing.add(job_id)
        written = 0
        for job_id, events in work.items():
            try:
                if events:
                    lines = [e.model_dump_json() for e in events]
                    self.store.put_event_batch(job_id, events[0].id, lines)
                    written += 1
            except (OSError, NotFoundError, ValueError) as exc:
                log.warning("job %s: %d events not archived yet (%s); retrying", job_id, len(events), exc)
                with self._cond:  # keep them, before any newer ones, for the next flush
                    self._pending[job_id] = events + self._pending.get(job_id, [])
                    self._since.setdefault(job_id, now)
            finally:
                with self._cond:
                    self._writing.discard(job_id)
                    self._cond.notify_all()
        self.batches += written
        return written

    def run(self, stop: threading.Event) -> None:
        """Write batches as they fall due until ``stop`` is set, then everything left."""
        while not stop.wait(self.flush_s / 4):
            self.flush()
        self.flush(due_only=False)
