"""Every Redis key the distributed runtime uses, in one place (prefix configurable, default ``segue:``).

Queue (a Redis with ``maxmemory-policy noeviction``)::

    segue:queue:<principal>      a principal's waiting jobs (list of JSON entries; :mod:`workers.redis_queue`)
    segue:queues                 the waiting lists that hold jobs (sorted set, served round-robin by name)
    segue:queues:turn            the waiting list served last (the round-robin cursor)
    segue:queues:bell            one token per job queued: idle workers BLPOP it instead of polling
    segue:jobs                   stream of the jobs being run {job, kind, payload (JSON), owner, format,
                                 version}; consumer group ``segue-workers``
    segue:jobs:dead              dead letters: jobs delivered more than ``max_deliveries`` times
    segue:job:<job>              JobInfo JSON (status is a fold over the job's events)
    segue:job:<job>:terminal     SET NX by whoever publishes the job's terminal event (exactly once)
    segue:job:<job>:attempt      the run holding the job, its fencing token (:mod:`workers.fencing`)
    segue:events:<job>           the job's events, entry id ``<event id>-0``, field ``event`` = JobEvent JSON
    segue:events:<job>:seq       INCR gives the next event id: 1 (``queued``, by the API), 2, 3...
    segue:cancel:<job>           cancel flag (SET EX), polled by the worker through ``should_stop``
    segue:worker:<name>          worker heartbeat (SET EX ttl); its absence means the worker is dead
    segue:lock:build:<db>        build lock (SET NX EX, refreshed while building)
    segue:api:<uuid>:wake        per API process: a one-entry stream that wakes its blocked XREAD

Cache (may be a separate Redis with ``allkeys-lru``; losing it only costs a reload from disk)::

    segue:db:<key>:n             chunk count of a cached database object (``.npy`` bytes; key: its store key)
    segue:db:<key>:<i>           chunk ``i`` (4 MiB each, the last one shorter)
"""

from __future__ import annotations

from dataclasses import dataclass

DEFAULT_PREFIX = "segue:"
DEFAULT_GROUP = "segue-workers"
CHUNK_SIZE = 4 << 20
"""Database cache chunk size (bytes)."""
EVENTS_MAXLEN = 10_000
"""Approximate cap of a job's event stream (``XADD MAXLEN ~``)."""
DEAD_MAXLEN = 100_000
"""Approximate cap of the dead-letter stream."""


@dataclass(frozen=True, slots=True)
class RedisKeys:
    """Key names under one prefix (see the module docstring)."""

    prefix: str = DEFAULT_PREFIX
    group: str = DEFAULT_GROUP

    @property
    def jobs(self) -> str:
        return f"{self.prefix}jobs"

    def queue(self, principal: str) -> str:
        return f"{self.prefix}queue:{principal}"

    @property
    def queues(self) -> str:
        return f"{self.prefix}queues"

    @property
    def queues_turn(self) -> str:
        return f"{self.prefix}queues:turn"

    @property
    def bell(self) -> str:
        return f"{self.prefix}queues:bell"

    @property
    def dead(self) -> str:
        return f"{self.prefix}jobs:dead"

    def events(self, job_id: str) -> str:
        return f"{self.prefix}events:{job_id}"

    def event_seq(self, job_id: str) -> str:
        return f"{self.prefix}events:{job_id}:seq"

    def job(self, job_id: str) -> str:
        return f"{self.prefix}job:{job_id}"

    def terminal(self, job_id: str) -> str:
        return f"{self.prefix}job:{job_id}:terminal"

    def attempt(self, job_id: str) -> str:
        return f"{self.prefix}job:{job_id}:attempt"

    def cancel(self, job_id: str) -> str:
        return f"{self.prefix}cancel:{job_id}"

    def worker(self, name: str) -> str:
        return f"{self.prefix}worker:{name}"

    @property
    def worker_pattern(self) -> str:
        return f"{self.prefix}worker:*"

    def db_count(self, db_id: str) -> str:
        return f"{self.prefix}db:{db_id}:n"

    def db_chunk(self, db_id: str, index: int) -> str:
        return f"{self.prefix}db:{db_id}:{index}"

    def build_lock(self, db_id: str) -> str:
        return f"{self.prefix}lock:build:{db_id}"

    def api_wake(self, process_id: str) -> str:
        return f"{self.prefix}api:{process_id}:wake"
