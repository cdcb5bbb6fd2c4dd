"""Small jobs run for a request (:mod:`workers.tasks`): submitted through the job backend, awaited,
then removed.

The API process never does engine-sized work itself (parsing a large upload, retargeting, a large
export): it asks a worker, waits (at most :data:`TASK_WAIT_S`) and streams what the worker stored.
Requests asking for the same thing at once share one small job (by ``key``); a request that stops
waiting leaves the job running, so its answer is in the store for the next one.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Annotated, Any

from fastapi import Depends
from starlette.requests import HTTPConnection

from schemas import EventType
from schemas.jobs import JobKind
from workers.backend import JobBackend, JobNotFinished
from workers.store import NotFoundError, Store

from .errors import ApiError
from .jobs_common import RETRY_AFTER_S, submit_job
from .metrics import Metrics

log = logging.getLogger("segue.tasks")

TASK_WAIT_S = 300.0
"""Longest a request waits for its small job (then 503 with ``Retry-After``; the job goes on)."""
CLEANUP_TRIES = 100
"""Attempts (0.1 s apart) to remove a finished small job while its backend still holds it."""


class TaskRunner:
    """The small jobs of one API process, by key (see the module docstring)."""

    def __init__(self) -> None:
        self._pending: dict[str, asyncio.Future[dict[str, Any]]] = {}
        self._drivers: set[asyncio.Task[None]] = set()

    async def run(
        self,
        key: str,
        payload: dict[str, Any],
        store: Store,
        backend: JobBackend,
        metrics: Metrics,
        wait_s: float = TASK_WAIT_S,
        owner: str | None = None,
    ) -> dict[str, Any]:
        """The ``done`` data of the small job ``payload`` (one per ``key`` at a time), submitted as
        ``owner``'s (the principal whose request needs it: fair scheduling serves it in that
        principal's line; a request joining one already running leaves it the first one's).

        Raises :class:`~service.errors.ApiError`: the task's own error (its ``status`` and
        ``code``), 503 when the backend cannot take it, the job was lost or ``wait_s`` passed."""
        future = self._pending.get(key)
        if future is None:
            future = asyncio.get_running_loop().create_future()
            self._pending[key] = future
            driver = asyncio.create_task(self._drive(key, payload, future, store, backend, metrics, owner))
            self._drivers.add(driver)
            driver.add_done_callback(self._drivers.discard)
        try:
            outcome = await asyncio.wait_for(asyncio.shield(future), wait_s)
        except TimeoutError:
            raise ApiError(
                503,
                "task_pending",
                f"the server is still preparing this ({key.split(':', 1)[0]}); try again shortly",
                headers={"Retry-After": str(RETRY_AFTER_S)},
            ) from None
        if outcome["type"] == EventType.done:
            return dict(outcome["data"])
        error = outcome["data"].get("error") or {}
        code = str(error.get("code") or "task_failed")
        if outcome["type"] != EventType.failed:
            status = 503  # cancelled or lost: nothing wrong with the request
        elif code in ("time_limit", "memory_limit"):
            status, code = 413, "too_large"  # the worker's supervisor stopped it
        else:
            status = int(error.get("status") or 500)
        headers = {"Retry-After": str(RETRY_AFTER_S)} if status == 503 else None
        raise ApiError(
            status,
            code,
            str(error.get("message") or f"the worker could not finish this ({outcome['type']})"),
            headers=headers,
        )

    async def idle(self) -> None:
        """Wait until every small job this runner started has ended and been removed."""
        while self._drivers:
            await asyncio.gather(*self._drivers, return_exceptions=True)

    async def _drive(
        self,
        key: str,
        payload: dict[str, Any],
        future: asyncio.Future[dict[str, Any]],
        store: Store,
        backend: JobBackend,
        metrics: Metrics,
        owner: str | None,
    ) -> None:
        job_id: str | None = None
        try:
            info = await submit_job(store, backend, metrics, JobKind.task, payload, owner=owner)
            job_id = info.id
            outcome: dict[str, Any] = {"type": EventType.cancelled, "data": {}}
            async for event in backend.events(job_id):
                if event.type.terminal:
                    outcome = {"type": event.type, "data": event.data}
            future.set_result(outcome)
        except Exception as exc:
            if not future.done():
                future.set_exception(exc)
        finally:
            self._pending.pop(key, None)
            if future.done() and not future.cancelled():
                future.exception()  # retrieved: no "never retrieved" warning when nobody waited
        if job_id is not None:
            await _remove(backend, job_id)


async def _remove(backend: JobBackend, job_id: str) -> None:
    """Delete a finished small job (its record, events, staged data), retrying while the backend
    still counts it as running (its terminal event arrives before its worker is released)."""
    for _ in range(CLEANUP_TRIES):
        try:
            await backend.delete(job_id)
            return
        except JobNotFinished:
            await asyncio.sleep(0.1)
        except NotFoundError:
            return
        except Exception:  # the backend is away: the record stays, hidden from listings
            log.warning("could not remove small job %s", job_id, exc_info=True)
            return


def task_runner(conn: HTTPConnection) -> TaskRunner:
    """The app's :class:`TaskRunner` (made on first use)."""
    runner: TaskRunner | None = getattr(conn.app.state, "task_runner", None)
    if runner is None:
        runner = conn.app.state.task_runner = TaskRunner()
    return runner


TaskRunnerDep = Annotated[TaskRunner, Depends(task_runner)]
