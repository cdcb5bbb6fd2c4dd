"""Per-principal limits: unfinished jobs (``SEGUE_MAX_QUEUED_JOBS``) and live sessions
(``SEGUE_MAX_SESSIONS``). Over a limit the answer is 429 ``too_many_jobs`` / ``too_many_sessions``
with ``Retry-After``.

The job count is kept per principal as the set of its jobs that may still be unfinished: loaded from
the store at start-up, grown at each submission and pruned (status read from the store, which every
backend keeps in step) when it reaches the limit, so a check costs nothing until a principal is
near its limit, and then only a read of its own unfinished jobs.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager

from schemas.jobs import JobKind
from workers.store import NotFoundError, Store

from .errors import ApiError

RETRY_AFTER_S = 5


class JobQuota:
    """Unfinished jobs per principal (see the module docstring)."""

    def __init__(self, store: Store, limit: int) -> None:
        self.store, self.limit = store, limit
        self._open: dict[str, set[str]] = defaultdict(set)
        for info in store.list_jobs():
            if not info.status.finished and info.kind != JobKind.task:  # small jobs: the server's own
                self._open[info.owner or ""].add(info.id)

    def _prune(self, owner: str) -> set[str]:
        jobs = self._open[owner]
        for job_id in list(jobs):
            try:
                finished = self.store.job_info(job_id).status.finished
            except NotFoundError:
                finished = True
            if finished:
                jobs.discard(job_id)
        return jobs

    def check(self, owner: str) -> None:
        """429 when ``owner`` has ``limit`` unfinished jobs."""
        if len(self._open[owner]) < self.limit or len(self._prune(owner)) < self.limit:
            return
        raise ApiError(
            429,
            "too_many_jobs",
            f"you have {self.limit} unfinished jobs (SEGUE_MAX_QUEUED_JOBS); wait for some to end",
            {"limit": self.limit},
            headers={"Retry-After": str(RETRY_AFTER_S)},
        )

    def add(self, owner: str, job_id: str) -> None:
        self._open[owner].add(job_id)


class SessionQuota:
    """Live sessions per principal."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._live: dict[str, int] = defaultdict(int)

    def refusal(self, owner: str) -> ApiError | None:
        """The 429 to answer when ``owner`` has ``limit`` live sessions (None when it may open one)."""
        if self._live[owner] < self.limit:
            return None
        return ApiError(
            429,
            "too_many_sessions",
            f"you have {self.limit} live sessions (SEGUE_MAX_SESSIONS); close one first",
            {"limit": self.limit},
            headers={"Retry-After": str(RETRY_AFTER_S)},
        )

    @contextmanager
    def hold(self, owner: str) -> Iterator[None]:
        self._live[owner] += 1
        try:
            yield
        finally:
            self._live[owner] -= 1
