"""Creating jobs: ids, the stored JobInfo and request, submission to the backend, metrics."""

from __future__ import annotations

import uuid
from typing import Any

from schemas import JobInfo, JobStatus
from schemas.jobs import JobKind
from workers.backend import JobBackend
from workers.store import Store, now

from .metrics import Metrics


def new_job_id() -> str:
    """A fresh job id (32 hex digits)."""
    return uuid.uuid4().hex


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
) -> JobInfo:
    """Store a queued job with its request (``{"kind", "payload"}``) and hand it to the backend."""
    info = JobInfo(
        id=job_id or new_job_id(),
        kind=kind,
        engine=engine,
        database=database,
        status=JobStatus.queued,
        created_at=now(),
    )
    store.put_job(info, {"kind": kind.value, "payload": payload})
    submitted = await backend.submit(info, kind.value, payload)
    metrics.inc("segue_jobs_submitted_total", kind=kind.value)
    return submitted
