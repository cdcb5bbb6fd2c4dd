"""``segue worker``: a process that runs jobs from the Redis jobs stream (any number, any machine).

Protocol (key names in :mod:`workers.redis_keys`):

- **Delivery.** Jobs wait in one list per principal; a worker with nothing to do takes the next
  principal's next job (round-robin, :mod:`workers.redis_queue`), which puts it in ``segue:jobs``
  and reads it for this worker (consumer group ``segue-workers``) in one atomic step, and waits on
  the queue's bell when there is none. An entry stays in the group's pending list until the job's
  terminal event is published; then ``XACK`` + ``XDEL``.
- **Versions.** A job whose entry carries another job format or package version than this worker's
  (:mod:`workers.version`) is refused with an error log and given back to its principal's list; the
  worker then takes nothing for ``refuse_backoff_s``.
- **A full cache disk.** A run whose engine process cannot cache the job's database even after
  evicting every other (:class:`~workers.dbcache.CacheFull`) is logged for the operator and the job
  given back, marked, for a worker that has not failed it; when every live worker has, it fails
  with code ``cache_full``.
- **Heartbeats.** A background thread ``SET segue:worker:<name> ... EX ttl`` every ``heartbeat_s``.
  While a job runs it also resets the entry's idle time (``XCLAIM ... JUSTID``, only if the entry is
  still ours) until the job's deadline (2 × budget + grace; builds: one hour), and extends the build
  lock it holds.
- **Reclaim.** Before reading, a worker scans ``XPENDING``: entries of consumers whose heartbeat key
  is gone (the worker died), and entries idle longer than ``reclaim_idle_s`` (a hung worker: its
  heartbeat thread stopped refreshing them), are taken over with ``XCLAIM`` (``min-idle-time`` makes
  the takeover race-free: only one worker wins). At start-up a worker also takes back what a previous
  process with its name left pending.
- **Dead letters.** An entry delivered more than ``max_deliveries`` times (its workers keep dying) is
  copied to ``segue:jobs:dead``, its job fails with code ``dead_letter``, and it is acked and deleted.
  Malformed entries go there directly.
- **Idempotency.** Event publishing drops anything after a job's terminal event (exactly one terminal
  event, :mod:`workers.redis_events`); a delivered job that already ended (terminal marker in Redis or
  a finished status on disk) is acked and skipped. A job re-run after its worker died publishes a
  second ``started`` (its data names the worker and the attempt) and continues the same event ids.
- **Fencing.** Each run takes the job's next attempt (:mod:`workers.fencing`) before it starts; its
  events are published only while it holds it, its engine process checks it before every write and
  stops its search once it is lost. A worker that hung past ``reclaim_idle_s`` (SIGSTOP, a frozen
  VM) and resumes finds its events refused: it cancels its run, publishes nothing and acks nothing
  (acks only ever remove an entry this worker still owns).
- **Cancel.** ``should_stop`` checks ``segue:cancel:<job>`` (and the terminal marker) at most every
  50 ms; :func:`workers.execute.execute_job` then publishes ``cancelled`` with the best result so far.
- **Databases.** Memory-mapped from the worker's local copy (:meth:`~workers.store.Store.database_dir`:
  the store's own files when local, else downloaded once from the object store, small objects
  through the Redis cache :mod:`workers.redis_cache`); loaded engines stay in a per-worker LRU
  bounded by bytes (:class:`~workers.engine_cache.EngineCache`).
  A build takes ``segue:lock:build:<db>`` (``SET NX EX``); a second build of the same database waits
  for the lock, then reuses the ready database instead of building it again.
- **History.** Every event the worker publishes is also copied to the store in batches
  (:mod:`workers.event_archive`, a thread of its own), so a Redis that loses its memory loses none.
- **Housekeeping.** A thread removes staged uploads older than ``staged_max_age_s`` (orphans of
  parses whose processes were lost) every ``staged_sweep_s``.
- **Stopping.** SIGTERM/SIGINT: finish the current job, then exit. A second signal releases the job
  at once (not acked; the heartbeat key is deleted so another worker reclaims it immediately).

All processes share one store (``SEGUE_STORE_URL``, or one data directory); a worker's own
``SEGUE_DATA_DIR`` is then only its cache.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import socket
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from types import FrameType
from typing import Any, cast

import redis

from engines.registry import warm_compiled
from schemas import DatabaseStatus, EventType

from .budget import shortfall
from .event_archive import BatchArchiver
from .fencing import ACQUIRE_LUA, StaleAttempt
from .records import sweep_staged
from .redis_events import EventPublisher
from .redis_keys import DEAD_MAXLEN, RedisKeys
from .redis_queue import BELL_MAX, RELEASE_LUA, TAKE_LUA, entry_of_fields, principal_list
from .settings import Settings
from .store import NotFoundError, Store
from .supervisor import (
    ChildConfig,
    EngineProcess,
    Outcome,
    Task,
    engine_plugins,
    request_budget_s,
    terminal_after_kill,
    time_limit,
)
from .version import mismatch, stamp

log = logging.getLogger("segue.redis.worker")

# Reset the idle time of an entry we still own (so the idle backstop leaves running jobs alone).
_TOUCH_LUA = """
local p = redis.call('XPENDING', KEYS[1], ARGV[1], ARGV[3], ARGV[3], 1)
if #p == 0 or p[1][2] ~= ARGV[2] then return 0 end
redis.call('XCLAIM', KEYS[1], ARGV[1], ARGV[2], 0, ARGV[3], 'JUSTID')
return 1
"""
# Extend / release a lock only while it holds our token.
_EXTEND_LUA = """
if redis.call('GET', KEYS[1]) == ARGV[1] then return redis.call('PEXPIRE', KEYS[1], ARGV[2]) end
return 0
"""
_RELEASE_LUA = """
if redis.call('GET', KEYS[1]) == ARGV[1] then return redis.call('DEL', KEYS[1]) end
return 0
"""
# Ack and delete an entry only while it is pending for us (a worker that hung and lost the entry to
# another worker must not remove it from under that worker).
_ACK_LUA = """
local p = redis.call('XPENDING', KEYS[1], ARGV[1], ARGV[3], ARGV[3], 1)
if #p == 0 or p[1][2] ~= ARGV[2] then return 0 end
redis.call('XACK', KEYS[1], ARGV[1], ARGV[3])
redis.call('XDEL', KEYS[1], ARGV[3])
return 1
"""

Entry = tuple[str, dict[str, str], int]
"""A delivered jobs-stream entry: id, fields, delivery count."""


@dataclass(slots=True)
class _Running:
    """The job a worker is running (read by the heartbeat thread)."""

    entry_id: str
    job_id: str
    deadline: float
    lock: tuple[str, str] | None = None


CACHE_FULL_FIELD = "cache_full"
"""A given-back job's field naming the workers whose cache disk had no room for it."""


class _Released(Exception):
    """The engine process gave the job back: this host cannot run it (its cache disk is full)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def _marks(fields: dict[str, str]) -> list[str]:
    """The workers whose cache had no room for a job (its :data:`CACHE_FULL_FIELD`)."""
    return [name for name in fields.get(CACHE_FULL_FIELD, "").split(",") if name]


def default_name() -> str:
    """A unique consumer name: host, pid and a random suffix."""
    return f"{socket.gethostname()}-{os.getpid()}-{uuid.uuid4().hex[:6]}"


class Worker:
    """One worker process's loop (see the module docstring)."""

    def __init__(self, settings: Settings) -> None:
        redis_url = settings.redis_url
        if not redis_url:
            raise ValueError("a worker needs the queue's Redis: give --redis or set SEGUE_REDIS_URL")
        if settings.heartbeat_ttl_s <= settings.heartbeat_s:
            raise ValueError("heartbeat_ttl_s must be longer than heartbeat_s")
        self.settings = s = settings
        self.name = s.worker_name or default_name()
        self.keys = RedisKeys(s.redis_prefix)
        self.store = Store.from_settings(s)
        # blocking reads must end before the socket timeout (redis-py's default is 5 s)
        timeout = s.block_ms / 1000 + 5
        self.client = redis.Redis.from_url(redis_url, decode_responses=True, socket_timeout=timeout)
        cache_url = s.redis_cache_url or redis_url
        self.cache_client = redis.Redis.from_url(cache_url)
        self.archiver = BatchArchiver(self.store, s.event_archive_s)
        self.publisher = EventPublisher(self.client, self.store, self.keys, archiver=self.archiver)
        config = ChildConfig(
            store_root=self.store.url,
            plugins=engine_plugins(s.engine_plugins),
            engine_cache_bytes=s.engine_cache_mb << 20,
            cache_url=cache_url,
            prefix=s.redis_prefix,
            chunk_size=s.cache_chunk_bytes,
            cache_dir=str(self.store.root),
            disk_cache_bytes=s.disk_cache_mb << 20,
            cache_max_object_bytes=s.cache_max_object_mb << 20,
            fence_url=redis_url,
        )
        self.engine = EngineProcess(
            self.name,
            config,
            self._relay_event,
            self._relay_end,
            cancel_grace_s=s.cancel_grace_s,
            max_rss_bytes=s.max_rss_bytes,
            load_timeout_s=s.load_timeout_s,
        )
        self._touch = self.client.register_script(_TOUCH_LUA)
        self._extend = self.client.register_script(_EXTEND_LUA)
        self._release = self.client.register_script(_RELEASE_LUA)
        self._ack_owned = self.client.register_script(_ACK_LUA)
        self._acquire_lua = self.client.register_script(ACQUIRE_LUA)
        self._take_lua = self.client.register_script(TAKE_LUA)
        self._release_lua = self.client.register_script(RELEASE_LUA)
        self._running: _Running | None = None
        self._stop = threading.Event()
        self._next_reclaim = 0.0
        self._next_cleanup = 0.0
        self.processed = 0

    # -- main loop ----------------------------------------------------------------------------
    def run(self, stop: threading.Event | None = None) -> int:
        """Process jobs until ``stop`` is set; returns the number of jobs processed."""
        if stop is not None:
            self._stop = stop
        beat_stop = threading.Event()
        beater = threading.Thread(
            target=self._heartbeat_loop, args=(beat_stop,), name="segue-heartbeat", daemon=True
        )
        sweeper = threading.Thread(
            target=self._sweep_loop, args=(beat_stop,), name="segue-sweep", daemon=True
        )
        archiving = threading.Thread(
            target=self.archiver.run, args=(beat_stop,), name="segue-event-archive", daemon=True
        )
        startup = True
        backoff = 0.1
        try:
            while not self._stop.is_set():  # Redis may come up after the workers (docker compose)
                try:
                    self._ensure_group()
                    self._announce("{}")
                    break
                except (redis.AuthenticationError, redis.exceptions.AuthorizationError) as exc:
                    raise redis.AuthenticationError(
                        f"Redis refused this worker's credentials ({exc}): check the password in "
                        "SEGUE_REDIS_URL (redis://:PASSWORD@host:port/0)"
                    ) from None
                except (redis.ConnectionError, redis.TimeoutError) as exc:
                    log.warning("waiting for Redis (%s); retrying in %.1f s", exc, backoff)
                    self._stop.wait(backoff)
                    backoff = min(backoff * 2, 5.0)
            if self._stop.is_set():
                return self.processed
            self._beat()
            beater.start()
            sweeper.start()
            archiving.start()
            self.engine.start()
            while not self.engine.ready.wait(0.2):  # spawning + imports take ~1 s
                if self._stop.is_set():
                    return self.processed
            log.info("worker %s ready (group %s on %s)", self.name, self.keys.group, self.keys.jobs)
            while not self._stop.is_set():
                try:
                    entry = self._reclaim(startup)
                    startup = startup and entry is not None  # at start-up: until nothing is left
                    if entry is None:
                        entry = self._read()
                    if entry is not None:
                        self._process(entry)
                    backoff = 0.1
                except redis.ResponseError as exc:
                    if "NOGROUP" in str(exc):
                        log.warning("the jobs stream or group is gone (Redis flushed?); recreating it")
                        self._ensure_group()
                        continue
                    log.exception("Redis refused a command; retrying in %.1f s", backoff)
                    self._stop.wait(backoff)
                    backoff = min(backoff * 2, 5.0)
                except (redis.ConnectionError, redis.TimeoutError) as exc:
                    log.warning("Redis unavailable (%s); retrying in %.1f s", exc, backoff)
                    self._stop.wait(backoff)
                    backoff = min(backoff * 2, 5.0)
                    startup = True
                except Exception:  # e.g. the store's disk: the entry stays pending and is retried later
                    log.exception(
                        "worker %s: job processing failed; continuing in %.1f s", self.name, backoff
                    )
                    self._stop.wait(backoff)
                    backoff = min(backoff * 2, 5.0)
                    startup = True  # take our own pending entry back at once
        finally:
            self.engine.close()
            beat_stop.set()
            for thread in (beater, sweeper, archiving):
                if thread.is_alive():
                    thread.join(timeout=5)
            # gone at once: other workers reclaim anything we leave pending without waiting the TTL
            with contextlib.suppress(redis.RedisError):
                self.client.delete(self.keys.worker(self.name))
            self.client.close()
            self.cache_client.close()
            log.info("worker %s stopped after %d jobs", self.name, self.processed)
        return self.processed

    def _ensure_group(self) -> None:
        try:
            self.client.xgroup_create(self.keys.jobs, self.keys.group, id="0", mkstream=True)
        except redis.ResponseError as exc:
            if "BUSYGROUP" not in str(exc):
                raise

    def _read(self) -> Entry | None:
        """The next job, from the principals' waiting lists in turn (:mod:`workers.redis_queue`);
        when there is none, wait for the bell (at most ``block_ms``) and look once more."""
        entry = self._take()
        if entry is None:
            self.client.blpop([self.keys.bell], timeout=self.settings.block_ms / 1000)
            entry = self._take()
        return entry

    def _take(self) -> Entry | None:
        keys = [self.keys.queues, self.keys.queues_turn, self.keys.jobs]
        got = cast(list[str] | None, self._take_lua(keys=keys, args=[self.keys.group, self.name]))
        if not got:
            return None
        entry_id, flat = got[0], got[1:]
        return str(entry_id), dict(zip(flat[::2], flat[1::2], strict=True)), 1

    def _give_back(self, entry_id: str, fields: dict[str, str], why: str) -> bool:
        """Put a job this worker will not run back first in its principal's waiting list (acked and
        removed from the stream in the same step); False when the entry is no longer ours."""
        keys = [
            self.keys.jobs,
            principal_list(self.keys, fields.get("owner")),
            self.keys.queues,
            self.keys.bell,
        ]
        args: list[str | int] = [self.keys.group, self.name, entry_id, entry_of_fields(fields), BELL_MAX]
        given = bool(self._release_lua(keys=keys, args=args))
        if given:
            log.warning("job %s given back to the queue: %s", fields.get("job"), why)
        return given

    # -- housekeeping ---------------------------------------------------------------------------
    def _sweep_loop(self, stop: threading.Event) -> None:
        """Every ``staged_sweep_s``: remove orphaned staged uploads (:meth:`Store.sweep_staged`);
        in its own thread, so a slow store never holds up heartbeats or jobs."""
        while True:
            sweep_staged(self.store, self.settings.staged_max_age_s)
            if stop.wait(self.settings.staged_sweep_s):
                return

    # -- heartbeats -----------------------------------------------------------------------------
    def _heartbeat_loop(self, beat_stop: threading.Event) -> None:
        while not beat_stop.wait(self.settings.heartbeat_s):
            self._beat()

    def _announce(self, info: str) -> None:
        """Set this worker's heartbeat key (alive for ``heartbeat_ttl_s``)."""
        self.client.set(self.keys.worker(self.name), info, px=int(self.settings.heartbeat_ttl_s * 1000))

    def _beat(self) -> None:
        running = self._running
        info = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "job": running.job_id if running else None,
            **stamp(),
        }
        try:
            self._announce(json.dumps(info))
            if running is None:
                return
            if time.monotonic() < running.deadline:
                self._touch(keys=[self.keys.jobs], args=[self.keys.group, self.name, running.entry_id])
            if running.lock is not None:
                self._extend(
                    keys=[running.lock[0]], args=[running.lock[1], int(self.settings.lock_ttl_s * 1000)]
                )
        except redis.RedisError as exc:
            log.warning("heartbeat failed: %s", exc)

    # -- reclaim and dead letters -----------------------------------------------------------------
    def _reclaim(self, startup: bool) -> Entry | None:
        """Take over one entry whose worker died or hung (None when there is none)."""
        now = time.monotonic()
        if not startup and now < self._next_reclaim:
            return None
        self._next_reclaim = now + self.settings.heartbeat_s / 2
        if now >= self._next_cleanup:
            self._next_cleanup = now + 60.0
            self._forget_dead_consumers()
        pending = cast(
            list[dict[str, Any]],
            self.client.xpending_range(self.keys.jobs, self.keys.group, "-", "+", count=100),
        )
        if not pending:
            return None
        others = sorted({str(p["consumer"]) for p in pending} - {self.name})
        with self.client.pipeline(transaction=False) as pipe:
            for consumer in others:
                pipe.exists(self.keys.worker(consumer))
            alive = dict(zip(others, (bool(x) for x in pipe.execute()), strict=True))
        idle_limit = int(self.settings.reclaim_idle_s * 1000)
        for p in pending:
            consumer, idle = str(p["consumer"]), int(p["time_since_delivered"])
            if consumer == self.name:
                stale, min_idle = startup or idle >= idle_limit, 0 if startup else idle_limit
            else:
                stale, min_idle = not alive[consumer] or idle >= idle_limit, max(idle // 2, 1)
            if not stale:
                continue
            entry_id = str(p["message_id"])
            claimed = cast(
                list[Any],
                self.client.xclaim(self.keys.jobs, self.keys.group, self.name, min_idle, [entry_id]),
            )
            if not claimed:
                continue  # another worker was faster
            _, fields = claimed[0]
            if not fields:  # deleted while pending
                self._ack(entry_id)
                continue
            deliveries = int(p["times_delivered"]) + 1
            why = "died" if consumer != self.name and not alive.get(consumer, True) else f"idle {idle} ms"
            log.warning(
                "reclaimed %s (job %s) from %s (%s), delivery %d",
                entry_id,
                fields.get("job"),
                consumer,
                why,
                deliveries,
            )
            return entry_id, dict(fields), deliveries
        return None

    def _forget_dead_consumers(self) -> None:
        """Remove group consumers with nothing pending whose heartbeat is gone (keeps XINFO short)."""
        try:
            consumers = self.client.xinfo_consumers(self.keys.jobs, self.keys.group)
        except redis.ResponseError:
            return
        for c in consumers:
            name = str(c["name"])
            idle_and_empty = int(c["pending"]) == 0 and int(c["idle"]) > 60_000
            if name != self.name and idle_and_empty and not self.client.exists(self.keys.worker(name)):
                self.client.xgroup_delconsumer(self.keys.jobs, self.keys.group, name)

    def _dead_letter(self, entry_id: str, fields: dict[str, str], deliveries: int, reason: str) -> None:
        job_id = fields.get("job")
        record: dict[Any, Any] = dict(fields)
        record.update(
            entry=entry_id,
            deliveries=str(deliveries),
            reason=reason,
            worker=self.name,
            time=f"{time.time():.3f}",
        )
        self.client.xadd(self.keys.dead, record, maxlen=DEAD_MAXLEN, approximate=True)
        log.error("job %s dead-lettered: %s", job_id, reason)
        if job_id:
            try:
                self.publisher.publish(
                    job_id, EventType.failed, {"error": {"code": "dead_letter", "message": reason}}
                )
            except NotFoundError:
                log.error("dead-lettered entry %s names an invalid job id %r", entry_id, job_id)
        self._ack(entry_id)

    def _ack(self, entry_id: str) -> None:
        """Ack and delete an entry if it is still pending for this worker."""
        if not self._ack_owned(keys=[self.keys.jobs], args=[self.keys.group, self.name, entry_id]):
            log.info("entry %s is no longer ours; not acknowledging it", entry_id)

    def _acquire(self, job_id: str, floor: int, held: int | None = None) -> int:
        """The job's next attempt (at least ``floor`` + 1 and above the store's record of it); 0 when
        the job has ended, -1 when ``held`` is given and another run holds the job now."""
        with contextlib.suppress(NotFoundError):
            floor = max(floor, self.store.job_info(job_id).attempt)
        keys = [self.keys.attempt(job_id), self.keys.terminal(job_id)]
        return int(self._acquire_lua(keys=keys, args=[floor, "" if held is None else held]))

    # -- one job ---------------------------------------------------------------------------------
    def _finished(self, job_id: str) -> bool:
        if self.client.exists(self.keys.terminal(job_id)):
            return True
        try:
            return self.store.job_info(job_id).status.finished
        except NotFoundError:
            return False

    def _process(self, entry: Entry) -> None:
        entry_id, fields, deliveries = entry
        try:
            job_id, kind = fields["job"], fields["kind"]
            payload = json.loads(fields["payload"])
            if not isinstance(payload, dict):
                raise ValueError("payload is not an object")
            self.store.check_id(job_id)
        except (KeyError, ValueError, NotFoundError) as exc:
            self._dead_letter(entry_id, fields, deliveries, f"malformed job entry: {exc}")
            return
        if self._finished(job_id):
            log.info("job %s already ended; dropping its entry %s", job_id, entry_id)
            self._ack(entry_id)
            return
        refused = mismatch(fields)
        if refused is not None:
            log.error(
                "worker %s refuses job %s: %s; run workers of the API's version (the job stays queued)",
                self.name,
                job_id,
                refused,
            )
            self._give_back(entry_id, fields, "another version")
            self._stop.wait(self.settings.refuse_backoff_s)  # leave it to a worker of its version
            return
        if deliveries > self.settings.max_deliveries:
            self._dead_letter(
                entry_id,
                fields,
                deliveries,
                f"job delivered {deliveries} times (limit {self.settings.max_deliveries}): "
                "its workers kept dying",
            )
            return
        if self.name in _marks(fields) and self._others(_marks(fields)):
            # this worker's cache had no room for it: leave it to another worker
            self._give_back(entry_id, fields, f"worker {self.name}'s cache disk had no room for it")
            self._stop.wait(0.5)
            return
        attempt = self._acquire(job_id, deliveries - 1)
        if attempt <= 0:
            log.info("job %s already ended; dropping its entry %s", job_id, entry_id)
            self._ack(entry_id)
            return
        self._running = _Running(entry_id, job_id, time.monotonic() + self._time_limit(kind, payload))
        released: str | None = None
        try:
            publish = self._publisher_for(job_id, attempt)
            should_stop = self._stop_check(job_id, attempt)
            if kind == "build" and isinstance(payload.get("database"), str):
                self._build(job_id, payload, publish, should_stop, attempt)
            else:
                self._supervised(job_id, kind, payload, attempt)
        except StaleAttempt as exc:
            log.warning("%s; this worker publishes nothing more of it", exc.message)
        except _Released as exc:
            released = exc.reason
        finally:
            self._running = None
            self.publisher.forget(job_id)
        if released is not None:
            self._cache_full(entry_id, fields, attempt, released)
            return
        self._ack(entry_id)
        self.processed += 1

    def _cache_full(self, entry_id: str, fields: dict[str, str], attempt: int, reason: str) -> None:
        """This host cannot cache the job's database (:class:`~workers.dbcache.CacheFull`): the
        operator is told, and the job goes back to the queue for a worker whose cache has not
        failed it; when every live worker's has, it fails naming the servers' problem (never the
        user's ``storage_full``)."""
        job_id = fields["job"]
        marks = [*_marks(fields), self.name]
        others = self._others(marks)
        log.error(
            "worker %s: %s; job %s %s",
            self.name,
            reason,
            job_id,
            "goes back to the queue for another worker" if others else "fails: no other worker can take it",
        )
        if others:
            self._give_back(entry_id, {**fields, CACHE_FULL_FIELD: ",".join(marks)}, "cache disk full")
            return
        message = (
            "no worker has room in its local cache for this job's database (the servers' disks are full; "
            "their operator is told in the worker logs); nothing is wrong with the request: submit it "
            "again later"
        )
        with contextlib.suppress(StaleAttempt):
            self.publisher.publish(
                job_id,
                EventType.failed,
                {"error": {"code": "cache_full", "message": message}},
                attempt=attempt,
            )
        self._ack(entry_id)

    def _others(self, marks: list[str]) -> list[str]:
        """Live workers (heartbeat keys) other than ``marks``."""
        cut = len(self.keys.worker(""))
        names = [str(k)[cut:] for k in self.client.scan_iter(match=self.keys.worker_pattern, count=500)]
        return sorted(set(names) - set(marks) - {self.name})

    # -- running a job in the engine process ------------------------------------------------------
    def _supervised(self, job_id: str, kind: str, payload: dict[str, Any], attempt: int) -> None:
        """Run a job in the engine process until it ends; a crashed run is run again (up to
        ``max_deliveries`` runs), a killed one gets its terminal event here."""
        while True:
            task, outcome, detail = self._run_once(job_id, kind, payload, attempt)
            if task.stale:
                return  # another run holds the job: nothing of this one is published
            if outcome == "released":
                raise _Released(detail)
            if outcome == "finished":
                if not task.terminal:
                    self._publish_safely(
                        task,
                        EventType.failed,
                        {"error": {"code": "internal", "message": "the job ended without a terminal event"}},
                    )
                return
            if task.terminal:
                return
            if outcome == "crashed":
                if self._stop_check(job_id, attempt)():
                    self._publish_safely(task, EventType.cancelled, {"result": task.best})
                    return
                if attempt >= self.settings.max_deliveries:
                    message = f"{detail}; gave up after {attempt} runs"
                    self._publish_safely(
                        task, EventType.failed, {"error": {"code": "worker_lost", "message": message}}
                    )
                    return
                attempt = self._acquire(job_id, attempt, held=attempt)
                if attempt <= 0:
                    return  # the job ended, or another run holds it
                log.warning("job %s: %s; running it again (attempt %d)", job_id, detail, attempt)
                continue
            type_, data = terminal_after_kill(outcome, task, detail)
            self._publish_safely(task, type_, data)
            return

    def _run_once(
        self, job_id: str, kind: str, payload: dict[str, Any], attempt: int
    ) -> tuple[Task, Outcome, str]:
        done = threading.Event()
        ending: dict[str, Any] = {}
        limit = time_limit(kind, payload, self.settings.job_grace_s, self.settings.build_timeout_s)
        task = Task(job_id, kind, payload, attempt=attempt, time_limit_s=limit)
        task.context = (self._publisher_for(job_id, attempt), done, ending)
        while not self.engine.run(task):  # the engine process is (re)starting
            self.engine.ready.wait(0.2)
        stop = self._stop_check(job_id, attempt)
        while not done.wait(self.settings.cancel_poll_s):
            if stop():
                self.engine.cancel(job_id)
        return task, ending["outcome"], ending["detail"]

    def _relay_event(self, task: Task, type_: EventType, data: dict[str, Any], when: float) -> None:
        """Supervisor thread: publish an event of the running job (retrying while Redis is away)."""
        if type_ == EventType.done and task.kind == "synth":
            short = shortfall(self.store, task.job_id, task.payload, data.get("result"))
            if short is not None:
                data = {**data, "short": short}
        self._publish_safely(task, type_, data)

    def _relay_end(self, task: Task, outcome: Outcome, detail: str) -> None:
        _, done, ending = task.context
        ending.update(outcome=outcome, detail=detail)
        done.set()

    def _publish_safely(self, task: Task, type_: EventType, data: dict[str, Any]) -> None:
        """Publish an event of a run (retrying while Redis is away); a run that lost its job is
        marked stale and stopped, and publishes nothing more."""
        if task.stale:
            return
        publish = task.context[0]
        deadline, backoff = time.monotonic() + self.settings.publish_retry_s, 0.1
        while True:
            try:
                publish(type_, data)
                return
            except StaleAttempt as exc:
                task.stale = True
                log.warning("%s; stopping this run, it publishes nothing more", exc.message)
                self.engine.cancel(task.job_id)
                return
            except (redis.ConnectionError, redis.TimeoutError) as exc:
                if time.monotonic() > deadline:
                    log.error(
                        "job %s: %s event lost, Redis unreachable for %.0f s (%s)",
                        task.job_id,
                        type_.value,
                        self.settings.publish_retry_s,
                        exc,
                    )
                    return
                time.sleep(backoff)
                backoff = min(backoff * 2, 2.0)

    def _time_limit(self, kind: str, payload: dict[str, Any]) -> float:
        """How long the job's entry is kept fresh (2 x budget_s + ``hang_grace_s``; builds their timeout)."""
        if kind == "build":
            return self.settings.build_timeout_s
        return 2 * request_budget_s(payload) + self.settings.hang_grace_s

    def _publisher_for(self, job_id: str, attempt: int) -> Callable[[EventType, dict[str, Any]], None]:
        def publish(type_: EventType, data: dict[str, Any]) -> None:
            if type_ == EventType.started:
                data = {**data, "worker": self.name, "attempt": attempt}
            self.publisher.publish(job_id, type_, data, attempt=attempt)

        return publish

    def _stop_check(self, job_id: str, attempt: int) -> Callable[[], bool]:
        """True once the job is cancelled, has ended, or another run took it (polled)."""
        keys = (self.keys.cancel(job_id), self.keys.terminal(job_id))
        attempt_key = self.keys.attempt(job_id)
        poll = self.settings.cancel_poll_s
        state = {"next": 0.0, "stop": False, "warned": False}

        def should_stop() -> bool:
            if state["stop"]:
                return True
            now = time.monotonic()
            if now >= state["next"]:
                state["next"] = now + poll
                try:
                    with self.client.pipeline(transaction=False) as pipe:
                        pipe.exists(*keys)
                        pipe.get(attempt_key)
                        ended, held = pipe.execute()
                    state["stop"] = bool(ended) or (held is not None and int(held) != attempt)
                    state["warned"] = False
                except redis.RedisError as exc:
                    if not state["warned"]:  # once per outage, not every poll
                        log.warning("cancel check failed: %s", exc)
                        state["warned"] = True
            return bool(state["stop"])

        return should_stop

    # -- builds ----------------------------------------------------------------------------------
    def _database_ready(self, db_id: str) -> bool:
        try:
            ready = self.store.database_info(db_id).status == DatabaseStatus.ready
            return ready and self.store.has_database_arrays(db_id)
        except NotFoundError:
            return False

    def _build(
        self,
        job_id: str,
        payload: dict[str, Any],
        publish: Callable[[EventType, dict[str, Any]], None],
        should_stop: Callable[[], bool],
        attempt: int = 1,
    ) -> None:
        db_id = str(payload["database"])
        lock_key, token = self.keys.build_lock(db_id), f"{self.name}/{job_id}/{uuid.uuid4().hex[:8]}"
        lock_px = int(self.settings.lock_ttl_s * 1000)
        next_check = 0.0
        while True:
            if self._database_ready(db_id):
                self._reuse_build(db_id, publish)
                return
            if self.client.set(lock_key, token, nx=True, px=lock_px):
                break
            if should_stop():
                publish(EventType.started, {})
                publish(EventType.cancelled, {"result": None})
                return
            if time.monotonic() >= next_check:
                next_check = time.monotonic() + self.settings.heartbeat_s
                self._break_stale_lock(lock_key)
            time.sleep(0.05)  # another worker builds this database: wait, then reuse its result
        running = self._running
        if running is not None:
            running.lock = (lock_key, token)
        try:
            if self._database_ready(db_id):
                self._reuse_build(db_id, publish)
                return
            self._supervised(job_id, "build", payload, attempt)
        finally:
            if running is not None:
                running.lock = None
            self._release(keys=[lock_key], args=[token])

    def _break_stale_lock(self, lock_key: str) -> None:
        """Delete a build lock whose holder's heartbeat is gone (it died mid-build)."""
        holder = cast(str | None, self.client.get(lock_key))
        if holder is None:
            return
        owner = holder.rsplit("/", 2)[0]
        dead = owner != self.name and not self.client.exists(self.keys.worker(owner))
        if dead and self._release(keys=[lock_key], args=[holder]):
            log.warning("build lock %s of dead worker %s released", lock_key, owner)

    def _reuse_build(self, db_id: str, publish: Callable[[EventType, dict[str, Any]], None]) -> None:
        log.info("database %s is ready already; not building it again", db_id)
        publish(EventType.started, {})
        publish(EventType.progress, {"fraction": 1.0, "message": "built by another job"})
        publish(EventType.done, {"result": None, "database": db_id, "reused": True})


# -- entry points ----------------------------------------------------------------------------------
def _install_signals(stop: threading.Event) -> Callable[[], None]:
    """SIGTERM/SIGINT: first finish the current job; a second signal releases it at once."""

    def handler(signum: int, frame: FrameType | None) -> None:
        if stop.is_set():
            log.warning("second signal: releasing the current job")
            raise KeyboardInterrupt
        log.info("signal %d: finishing the current job, then stopping (again to stop now)", signum)
        stop.set()

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGTERM, signal.SIGINT)}

    def restore() -> None:
        for sig, old in previous.items():
            signal.signal(sig, old)

    return restore


def run_worker(settings: Settings, stop: threading.Event | None = None) -> int:
    """Run a worker with ``settings`` until ``stop`` is set (or SIGTERM/SIGINT when called from the
    main thread); returns the number of jobs processed.

    The fields it reads (:class:`~workers.settings.Settings`): ``redis_url`` (the queue Redis,
    ``noeviction``), ``store_url`` (the store shared with the API; default ``data_dir``, then
    shared through a volume), ``data_dir`` (with an object store: this worker's local cache),
    ``worker_name`` (default host-pid-random),
    ``heartbeat_s`` / ``heartbeat_ttl_s`` (a worker silent for the TTL is dead), ``max_deliveries``,
    ``block_ms``, ``redis_prefix``, ``redis_cache_url`` (a separate ``allkeys-lru`` cache Redis),
    ``cache_chunk_bytes``, ``reclaim_idle_s`` (the backstop for hung workers), ``engine_cache_mb``,
    ``disk_cache_mb``, ``load_timeout_s``, ``cache_max_object_mb``, the job limits
    (``job_grace_s``, ``cancel_grace_s``, ``max_job_memory_mb``) and
    ``engine_plugins``.
    """
    from engines.registry import load_plugins
    from motion.allocator import tune_process

    tune_process()
    load_plugins(settings.engine_plugins)
    stop = stop or threading.Event()
    restore = _install_signals(stop) if threading.current_thread() is threading.main_thread() else None
    try:
        return Worker(settings).run(stop)
    finally:
        if restore is not None:
            restore()


def serve(settings: Settings, warm: bool = True) -> int:
    """Run a worker as a command: logging set up, the compiled kernels made ready before the first
    job (``warm``: :func:`engines.registry.warm_compiled`, a fraction of a second once numba's cache
    is warm), exit status 0, 1 (a bad setting, Redis refused) or 130 (interrupted)."""
    logging.basicConfig(
        level=settings.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    try:
        if warm:
            warm_compiled(log.info)
        run_worker(settings)
    except KeyboardInterrupt:
        return 130
    except (ValueError, redis.RedisError) as exc:
        log.error("worker stopped: %s", exc)
        return 1
    return 0
