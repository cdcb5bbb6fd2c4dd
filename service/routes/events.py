"""Job events: a WebSocket stream (``/v1/jobs/{id}/events``) and a plain-HTTP fallback.

The WebSocket relays the backend's events through a bounded per-socket
:class:`~service.streaming.EventQueue` (a slow client gets the newest solution), sends each as
``JobEvent`` JSON and closes with 1000 after the terminal event (``done``, ``failed`` or
``cancelled``). ``?after=N`` resumes after the last event a client saw. Close codes: 4401 missing or
invalid token (when the server cannot answer the handshake with HTTP 401), 4404 unknown job, 1011
backend error.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Annotated, TypeVar

import anyio
from fastapi import APIRouter, Query, WebSocket
from fastapi.websockets import WebSocketDisconnect
from starlette.websockets import WebSocketState

from engines.base import EngineError
from engines.registry import EngineClass, kind_class
from schemas import DatabaseInfo, EventType, JobEvent, JobInfo
from workers.backend import JobBackend
from workers.store import NotFoundError, Store

from ..deps import BackendDep, MetricsDep, Principal, PrincipalDep, SettingsDep, websocket_principal
from ..errors import ApiError, error_response, responses
from ..limits import SessionQuota
from ..metrics import Metrics
from ..owners import database_for, job_for
from ..settings import Settings
from ..streaming import EventQueue, pump

log = logging.getLogger("segue.service.events")

router = APIRouter(prefix="/v1/jobs", tags=["events"])

Owned = TypeVar("Owned")

After = Annotated[int, Query(ge=0, description="resume: only events with a larger id")]


async def collect_events(backend: JobBackend, job_id: str, after: int, wait: float) -> list[JobEvent]:
    """The events after ``after``: those recorded now (however long loading them from the store or
    Redis takes), and with ``wait`` > 0 every event until the job's terminal one or until ``wait``
    seconds have passed, whichever comes first (a long poll: a client that asks again with the
    last id misses nothing and is not answered empty at once while the job runs)."""
    out = await backend.backlog(job_id, after)
    if wait <= 0 or (out and out[-1].type.terminal):
        return out
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wait
    events = backend.events(job_id, out[-1].id if out else after)
    try:
        while (left := deadline - loop.time()) > 0:
            try:
                event = await asyncio.wait_for(anext(events), left)
            except (StopAsyncIteration, TimeoutError):
                break
            out.append(event)
            if event.type.terminal:
                return out
    finally:
        with contextlib.suppress(RuntimeError):
            await events.aclose()  # type: ignore[attr-defined]
    # the wait is over: what has arrived since, without waiting
    return out + await backend.backlog(job_id, out[-1].id if out else after)


@router.get("/{job_id}/events", response_model=list[JobEvent], responses=responses(401, 404, 422))
async def list_events(
    job_id: str,
    backend: BackendDep,
    principal: PrincipalDep,
    after: After = 0,
    wait: Annotated[
        float,
        Query(ge=0, le=60, description="long poll: wait up to this many seconds for the job to end"),
    ] = 0,
) -> list[JobEvent]:
    """The job's events after ``after`` (no streaming: poll with the last id, or use the WebSocket).

    Without ``wait`` the answer is what there is now; with ``wait=S`` it comes when the job ends
    (the terminal event is the last one) or after ``S`` seconds, holding every event in between."""
    job_for(principal, await backend.status(job_id))  # 404 for unknown jobs and other principals' jobs
    return await collect_events(backend, job_id, after, wait)


async def refuse_handshake(
    websocket: WebSocket,
    status: int,
    code: str,
    message: str,
    ws_code: int,
    headers: dict[str, str] | None = None,
) -> None:
    """Refuse a handshake: an HTTP response when the server supports it, else accept and close."""
    if "websocket.http.response" in websocket.scope.get("extensions", {}):
        if headers is None and status == 401:
            headers = {"WWW-Authenticate": "Bearer"}
        await websocket.send_denial_response(error_response(status, code, message, headers=headers))
        return
    await websocket.accept()
    await websocket.close(code=ws_code, reason=message[:120])


WebSocketToken = Annotated[str | None, Query(description="bearer token (or the Authorization header)")]


async def websocket_owned(
    websocket: WebSocket,
    settings: Settings,
    token: str | None,
    find: Callable[[Principal], Awaitable[Owned]],
) -> tuple[Principal, Owned] | None:
    """The caller of a WebSocket (header, else ``?token=``) and what it asks for (``find``, a
    lookup that raises ``NotFoundError`` for what the caller may not see), or None once the
    handshake is refused (401 / close 4401) or the socket closed with 4404."""
    principal = websocket_principal(websocket, settings, token)
    if isinstance(principal, ApiError):
        await refuse_handshake(websocket, 401, principal.code, principal.message, 4401)
        return None
    try:
        return principal, await find(principal)
    except NotFoundError as exc:
        await websocket.accept()
        await websocket.close(code=4404, reason=str(exc)[:120])
        return None


@contextlib.asynccontextmanager
async def live_session_database(
    websocket: WebSocket,
    settings: Settings,
    token: str | None,
    store: Store,
    quota: SessionQuota,
    database: str,
    check: Callable[[EngineClass, str], None],
) -> AsyncIterator[DatabaseInfo | None]:
    """The handshake of a live session on a database (rhythm and control sessions): the caller
    (:func:`websocket_owned`), a place in its session quota (HTTP 429 / close 4429), the socket
    accepted, and the database a ready one whose engine passes ``check(engine class, database
    id)`` (an ``EngineError`` says why not; else close 4400). Yields the database's info while the
    quota place is held, or None once the socket was refused or closed."""

    async def find(principal: Principal) -> DatabaseInfo:
        return await anyio.to_thread.run_sync(database_for, store, principal, database)

    owned = await websocket_owned(websocket, settings, token, find)
    if owned is None:
        yield None
        return
    principal, info = owned
    refusal = quota.refusal(principal.name)
    if refusal is not None:
        await refuse_handshake(websocket, 429, refusal.code, refusal.message, 4429, refusal.headers)
        yield None
        return
    with quota.hold(principal.name):
        await websocket.accept()
        try:
            check(kind_class(info.kind), info.id)
            if info.status.value != "ready":
                raise EngineError(f"database {database} is {info.status.value}, not ready")
        except EngineError as exc:
            await websocket.close(code=4400, reason=str(exc)[:120])
            yield None
            return
        yield info


async def _send_events(websocket: WebSocket, queue: EventQueue, metrics: Metrics) -> JobEvent | None:
    """Send queued events until the terminal one (returned) or the producer ends (None)."""
    while True:
        event = await queue.get()
        if event is None:
            return None
        await websocket.send_text(event.model_dump_json())
        metrics.inc("segue_events_sent_total")
        if event.type.terminal:
            return event


async def _until_disconnect(websocket: WebSocket) -> None:
    """Read (and ignore) client messages until the client goes away."""
    with contextlib.suppress(WebSocketDisconnect):
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return


async def _ending(backend: JobBackend, job_id: str, after: int) -> tuple[JobEvent | None, int, str]:
    """After the backend's iterator ended without a terminal event: a terminal event rebuilt from
    the job's status (when the client has not seen it), and the close code and reason."""
    info = await backend.status(job_id)
    if not info.status.finished:
        return None, 1011, "the event stream ended before the job finished; reconnect with after="
    if info.last_event <= after:
        return None, 1000, f"job {info.status.value}; no events after {after}"
    type_ = EventType(info.status.value)
    data: dict[str, object] = {"result": info.result}
    if type_ == EventType.failed:
        data = {"error": {"code": "failed", "message": info.error or "the job failed"}}
    when = (info.finished_at or info.created_at).timestamp()
    event = JobEvent(id=info.last_event, job=job_id, type=type_, time=when, data=data, attempt=info.attempt)
    return event, 1000, "finished"


@router.websocket("/{job_id}/events")
async def stream_events(
    websocket: WebSocket,
    job_id: str,
    backend: BackendDep,
    settings: SettingsDep,
    metrics: MetricsDep,
    after: After = 0,
    token: WebSocketToken = None,
) -> None:
    """Stream a job's events as JSON text messages, ending with the terminal event (see module doc)."""

    async def find(principal: Principal) -> JobInfo:
        return job_for(principal, await backend.status(job_id))

    if await websocket_owned(websocket, settings, token, find) is None:
        return
    await websocket.accept()
    metrics.inc("segue_ws_connections")
    relay = _Relay(websocket, backend, job_id, after, EventQueue(settings.ws_queue), metrics)
    try:
        await relay.run()
    finally:
        metrics.inc("segue_events_coalesced_total", relay.queue.dropped)
        metrics.inc("segue_ws_connections", -1)


class _Relay:
    """One socket's stream: a producer (backend -> queue), a watcher (client messages) and the sender."""

    def __init__(
        self,
        websocket: WebSocket,
        backend: JobBackend,
        job_id: str,
        after: int,
        queue: EventQueue,
        metrics: Metrics,
    ) -> None:
        self.websocket, self.backend, self.job_id, self.after = websocket, backend, job_id, after
        self.queue, self.metrics = queue, metrics
        self.error: Exception | None = None
        self.gone = False

    async def run(self) -> None:
        """Relay until the terminal event (then close 1000) or until the client goes away."""
        code, reason = 1000, ""
        async with anyio.create_task_group() as tg:
            tg.start_soon(self._produce)
            tg.start_soon(self._watch, tg.cancel_scope)
            try:
                last = await _send_events(self.websocket, self.queue, self.metrics)
                if last is None:
                    code, reason = await self._end_without_terminal()
            except (WebSocketDisconnect, RuntimeError, OSError):
                self.gone = True  # the client went away mid-send
            tg.cancel_scope.cancel()
        if not self.gone and self.websocket.client_state == WebSocketState.CONNECTED:
            with contextlib.suppress(RuntimeError, WebSocketDisconnect, OSError):
                await self.websocket.close(code=code, reason=reason)

    async def _produce(self) -> None:
        try:
            await pump(self.backend.events(self.job_id, self.after), self.queue)
        except Exception as exc:  # reported to the client as a 1011 close
            log.warning("event stream of job %s failed: %r", self.job_id, exc)
            self.error = exc

    async def _watch(self, scope: anyio.CancelScope) -> None:
        await _until_disconnect(self.websocket)
        self.gone = True
        scope.cancel()

    async def _end_without_terminal(self) -> tuple[int, str]:
        """The producer ended without a terminal event: an error, or a job that already finished."""
        if self.error is not None:
            return 1011, f"event stream error: {self.error}"[:120]
        synthetic, code, reason = await _ending(self.backend, self.job_id, self.after)
        if synthetic is not None:
            await self.websocket.send_text(synthetic.model_dump_json())
            self.metrics.inc("segue_events_sent_total")
        return code, reason
