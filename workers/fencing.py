"""Fencing tokens: every run of a job holds an attempt number, and only the newest run may write.

A run is one execution of a job by one worker: the first delivery, a re-delivery after its worker
died or hung past ``reclaim_idle_s``, a re-run after the engine process crashed. Before it starts, a
run takes the next attempt number (:data:`ACQUIRE_LUA`, atomic in Redis: ``segue:job:<job>:attempt``
is raised to ``max(current, floor) + 1``; the floor is the attempt the store's job record names, so
a Redis that lost its keys never hands out a number twice). From then on:

- **every event** it publishes carries the attempt and is published only while the key still holds
  it: the check is part of the publish's optimistic transaction (``WATCH`` on the key, then
  ``MULTI``/``EXEC``, which fails if another run took the job in between), so there is no window
  between the check and the write (:mod:`workers.redis_events`); a refused publish raises
  :class:`StaleAttempt` and the worker cancels its run and acknowledges nothing;
- **every durable write** of its engine process (results, database arrays and records, job records)
  is checked first (:class:`FencedStore`; a result is checked again once written and removed when
  the run lost its job meanwhile), and the engine's ``should_stop`` polls the key
  (:class:`Fence`), so a run that lost its job stops its search by itself even while its worker
  process is stopped (SIGSTOP) and cannot relay anything. A write is a file (or object) in the store,
  which Redis cannot make conditional: what makes a late write harmless is that a run's results are
  named by its attempt (``r1``... for the first, ``a2r1``... for the second), so it never replaces
  anything of another run, and a result is reachable only through an event, which is fenced.

Events published before any run (``queued``, a cancel while queued) carry attempt 0; the API
publishes a cancel of a queued job with attempt 0, refused once a run started (the run sees the
cancel flag instead).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Mapping
from typing import Any

import redis

from motion import Motion
from motion.bvh import BvhLimits
from schemas import ClipInfo, DatabaseInfo, JobInfo, Report

from .execute import JobFailure
from .store import Store

log = logging.getLogger("segue.fencing")

ACQUIRE_LUA = """
-- KEYS[1] the job's attempt key, KEYS[2] its terminal marker
-- ARGV[1] floor (the store's record), ARGV[2] the attempt the caller holds ('' : none)
-- returns the new attempt, 0 when the job has ended, -1 when another run holds it
if redis.call('EXISTS', KEYS[2]) == 1 then return 0 end
local raw = redis.call('GET', KEYS[1])
local current = tonumber(raw or '0')
if ARGV[2] ~= '' and raw and current ~= tonumber(ARGV[2]) then return -1 end
local n = math.max(current, tonumber(ARGV[1])) + 1
redis.call('SET', KEYS[1], n)
return n
"""


class StaleAttempt(JobFailure):
    """A run that lost its job to a later attempt: what it publishes or writes is refused."""

    def __init__(self, job_id: str, attempt: int, current: int | None = None) -> None:
        holder = f" (attempt {current} holds it)" if current is not None else ""
        super().__init__("stale_attempt", f"job {job_id}: attempt {attempt} lost the job{holder}")
        self.job_id, self.attempt, self.current = job_id, attempt, current


class Fence:
    """What an engine process knows of its run's token: ``current()`` reads the attempt key (a
    missing key, after Redis lost it, does not prove the run stale: the next publish restores it);
    once lost, always lost. A Redis error counts as current (logged once): the events, checked in
    Redis itself, stay the authority."""

    def __init__(
        self, client: redis.Redis, key: str, job_id: str, attempt: int, poll_s: float = 0.25
    ) -> None:
        self.client, self.key, self.job_id, self.attempt = client, key, job_id, attempt
        self.poll_s = poll_s
        self.outage_poll_s = 5.0
        """How long ``lost`` waits before reading the key again after Redis failed to answer."""
        self.lost_to: int | None = None
        self._next = 0.0
        self._warned = False

    def current(self) -> bool:
        if self.lost_to is not None:
            return False
        try:
            raw = self.client.get(self.key)
        except redis.RedisError as exc:
            self._next = time.monotonic() + self.outage_poll_s  # do not stall the engine on it
            if not self._warned:
                log.warning("job %s: the fencing token cannot be read (%s)", self.job_id, exc)
                self._warned = True
            return True
        self._warned = False
        if raw is not None and int(raw) != self.attempt:
            self.lost_to = int(raw)
            log.warning(
                "job %s: attempt %d lost the job to attempt %d; stopping",
                self.job_id,
                self.attempt,
                self.lost_to,
            )
            return False
        return True

    def lost(self) -> bool:
        """Polled by ``should_stop``: reads Redis at most every ``poll_s``."""
        now = time.monotonic()
        if self.lost_to is None and now >= self._next:
            self._next = now + self.poll_s
            self.current()
        return self.lost_to is not None

    def check(self) -> None:
        """Raise :class:`StaleAttempt` when another run holds the job."""
        if not self.current():
            raise StaleAttempt(self.job_id, self.attempt, self.lost_to)


class OwnerGone(JobFailure):
    """The engine process's owner (its worker, or the API of the embedded backend) is gone: nobody
    relays its events, so nothing it writes may be kept (it is about to be killed)."""

    def __init__(self, parent: int) -> None:
        super().__init__("worker_lost", f"the engine process's owner (pid {parent}) is gone")


class FencedStore(Store):
    """The store of an engine process: each durable write (results, database arrays and records,
    job records, clips and exports made by small jobs) checks first that the process's owner is
    still its parent (``parent``: a run whose worker died is stale whatever Redis says, and the
    only fence the embedded backend needs, its attempts living in the owner's memory) and then the
    running job's :class:`Fence` (``fence`` is set per task; None: the embedded backend)."""

    fence: Fence | None = None
    parent: int | None = None
    """The pid of the owner that started this engine process (None: not checked)."""

    def _check(self) -> None:
        if self.parent is not None and os.getppid() != self.parent:
            raise OwnerGone(self.parent)
        if self.fence is not None:
            self.fence.check()

    def put_clip(
        self, name: str, data: bytes, limits: BvhLimits | None = None, units: str | None = None
    ) -> ClipInfo:
        self._check()
        return super().put_clip(name, data, limits, units)

    def put_export(self, job_id: str, name: str, data: bytes) -> None:
        self._check()
        super().put_export(job_id, name, data)

    def put_result(self, job_id: str, result_id: str, motion: Motion, report: Report) -> None:
        """Write a result while the run holds its job; checked again once written, and removed when
        another run took the job (or the owner died) meanwhile (between the first check and the
        write, or while this process was stopped there), so a run leaves no result written after
        it lost its job."""
        self._check()
        super().put_result(job_id, result_id, motion, report)
        try:
            self._check()
        except JobFailure:
            self.delete_result(job_id, result_id)
            raise

    def put_database_arrays(self, db_id: str, arrays: Mapping[str, Any] | bytes) -> None:
        self._check()
        super().put_database_arrays(db_id, arrays)

    def put_database_info(self, info: DatabaseInfo, spec: dict[str, Any] | None = None) -> None:
        self._check()
        super().put_database_info(info, spec)

    def put_job(self, info: JobInfo, request: dict[str, Any] | None = None) -> None:
        self._check()
        super().put_job(info, request)
