"""Creating jobs: ids, the stored JobInfo and request, submission to the backend, metrics.

The job's record in the store is the source of truth (backends re-queue unfinished jobs from it after
a crash or a restart), so it is written before the backend is asked; when the backend cannot take
the job (Redis is down, the pool cannot start) the record is removed again and the client gets 503
with ``Retry-After``: no job is left ``queued`` that nothing will run.
"""

from __future__ import annotations

import uuid
from typing import Any

from schemas import JobInfo, JobStatus
from schemas.jobs import JobKind
from workers.backend import BackendUnavailable, JobBackend
from workers.store import Store, now

from .errors import ApiError
from .metrics import Metrics

RETRY_AFTER_S = 5
"""What a 503 for an unavailable backend suggests (seconds)."""


def new_job_id() -> str:
    """A fresh job id (32 hex digits)."""
    return uuid.uuid4().hex


def unavailable(exc: Exception) -> ApiError:
    """503 ``backend_unavailable`` with ``Retry-After``."""
    return ApiError(
        503,
        "backend_unavailable",
        f"the job backend cannot take jobs now ({exc}); nothing was stored, try again",
        headers={"Retry-After": str(RETRY_AFTER_S)},
    )


async def submit_job(
    store: Store,
    backend: JobBackend,
    metrics: Metrics,
    kind: JobKind,
    payload: dict[str, Any],
    *,
    job_id: str | None = None,
    engine: str | None = None,
    database: str | None = None,
    owner: str | None = None,
) -> JobInfo:
    """Store a queued job with its request (``{"kind", "payload"}``) and hand it to the backend
    (503 and no record when the backend cannot take it)."""
    info = JobInfo(
        id=job_id or new_job_id(),
        kind=kind,
        engine=engine,
        database=database,
        status=JobStatus.queued,
        created_at=now(),
        owner=owner,
    )
    store.put_job(info, {"kind": kind.value, "payload": payload})
    try:
        submitted = await backend.submit(info, kind.value, payload)
    except BackendUnavailable as exc:
        store.discard_job(info.id)
        metrics.inc("segue_jobs_refused_total", reason="backend_unavailable")
        raise unavailable(exc) from None
    metrics.inc("segue_jobs_submitted_total", kind=kind.value)
    return submitted
