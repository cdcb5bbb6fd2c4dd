"""The store's durable copies of live state, written by the process that owns the run.

Live state (events, status) is in Redis or the API's memory; the store keeps the copies that
survive them: a job's ``info.json`` at every status change and a database's record when its build
ends. Both are written after the event that changes them was accepted (fenced, see
:mod:`workers.fencing`), and neither goes backwards:

- :func:`put_job_record`: a job's record is replaced only by a newer one (a higher
  ``last_event``) and never after it says finished, so a run resumed from SIGSTOP between its
  publish and its write cannot put back an older status;
- :func:`settle_database`: a build's terminal event leaves its database ``ready`` (the build wrote
  it) or ``failed`` with the reason: a cancelled build, a killed one (time, memory, cancel grace), a
  dead-lettered or lost one. Only the record's own build job settles it (``build_job``), so the end
  of an older build of the same spec never touches a newer one's record. ``POST /v1/databases``
  with a failed database's spec builds it again. A build's engine process writes ``building`` and
  ``ready`` only: a ``failed`` record is always this function's, with the terminal event's reason;
- :func:`settle_task`: a small job's terminal event removes the upload it was to parse.
"""

from __future__ import annotations

import logging

from schemas import DatabaseStatus, JobEvent, JobInfo
from schemas.jobs import JobKind

from .store import NotFoundError, Store

log = logging.getLogger("segue.records")


def put_job_record(store: Store, info: JobInfo) -> bool:
    """Write ``info`` as the job's record unless the stored one is finished or newer; True if written."""
    try:
        stored = store.job_info(info.id)
    except NotFoundError:
        stored = None
    if stored is not None and (stored.status.finished or stored.last_event >= info.last_event):
        return False
    store.put_job(info)
    return True


def _reason(event: JobEvent) -> str:
    if event.type.value == "cancelled":
        return "the build was cancelled"
    if event.type.value == "failed":
        error = event.data.get("error")
        message = error.get("message") if isinstance(error, dict) else None
        return str(message or "the build failed")
    return "the build ended without writing the database"


def settle(store: Store, job: JobInfo, event: JobEvent) -> None:
    """Everything a job's terminal ``event`` settles in the store: a build's database record
    (:func:`settle_database`), a small job's staged upload (:func:`settle_task`)."""
    settle_database(store, job, event)
    settle_task(store, job, event)


def settle_task(store: Store, job: JobInfo, event: JobEvent) -> None:
    """After a small job's terminal ``event``, whatever it was (done, failed by its parse, killed by
    its time or memory limit, dead-lettered, cancelled): the staged upload it was to read is removed
    (:meth:`Store.delete_staged`), so no outcome leaves one behind."""
    if job.kind != JobKind.task or not event.type.terminal:
        return
    try:
        request = store.job_request(job.id)
    except NotFoundError:
        return
    payload = request.get("payload")
    task = payload.get("request") if isinstance(payload, dict) else None
    staged = task.get("staged") if isinstance(task, dict) else None
    if not isinstance(staged, str):
        return
    try:
        store.delete_staged(staged)
    except NotFoundError:  # not a valid key: nothing was staged under it
        return
    except OSError as exc:  # the store is away: the sweep removes it later
        log.warning("job %s: its staged upload %s stays for the sweep (%s)", job.id, staged, exc)


def settle_database(store: Store, job: JobInfo, event: JobEvent) -> None:
    """After a build job's terminal ``event``: its database ends ``ready`` or ``failed`` (see the
    module docstring); nothing for other jobs and events."""
    if job.kind != JobKind.build or not job.database or not event.type.terminal:
        return
    try:
        db = store.database_info(job.database)
    except NotFoundError:
        return
    if db.status in (DatabaseStatus.ready, DatabaseStatus.failed):
        return
    if db.build_job is not None and db.build_job != job.id:
        return  # a newer build of the same spec owns the record
    reason = _reason(event)
    store.put_database_info(db.model_copy(update={"status": DatabaseStatus.failed, "error": reason}))
    log.warning("database %s: %s (job %s)", db.id, reason, job.id)


def sweep_staged(store: Store, max_age_s: float) -> list[str]:
    """Remove staged uploads older than ``max_age_s`` (:meth:`Store.sweep_staged`), logged for the
    operator; a store error is logged and the next sweep tries again. The keys removed."""
    try:
        removed = store.sweep_staged(max_age_s)
    except OSError as exc:
        log.warning("the staged-upload sweep could not run (%s); it runs again later", exc)
        return []
    if removed:
        log.warning(
            "removed %d staged upload(s) older than %.0f s that no job removed: %s",
            len(removed),
            max_age_s,
            ", ".join(removed[:10]),
        )
    return removed
