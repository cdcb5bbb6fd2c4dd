"""Live control: ``WebSocket /v1/sessions/control?database=<id>&latency_s=2`` — a follower (or walker)
generated while the leader's pose (or a path) streams in (:class:`engines.base.LiveControlSession`;
the control engine's :class:`engines.control.session.LiveControl`).

Protocol (JSON text messages):

* server -> client, first: ``{"type": "skeleton", "names", "parents", "offsets", "fps", "latency_s",
  "latency_frames", "control": "pose"|"path", "control_joints", ...}``.
* client -> server: ``{"type": "pose", "frames": [[[x, y, z], ...], ...]}`` (a dance database: per
  frame the ``control_joints``' world positions, metres, Y up, at ``fps``) or ``{"type": "path",
  "points": [[x, z], ...]}`` (a walk database), at most 240 frames per message; ``{"type": "stop"}``
  when the control ends.
* server -> client, one per ``pose``/``path`` message: ``{"type": "frames", "start": i, "fps": f,
  "root": [[x, y, z], ...], "rotations": [[[x, y, z, w], ...], ...]}`` — the target frames that
  became final (possibly none): target frame ``i`` is sent as soon as control frame
  ``i + latency_frames`` has arrived; after ``stop``, the remaining frames, then ``{"type": "end",
  "frames", "solves"}`` and close 1000. ``{"type": "error", "message"}`` for a bad message (the
  session goes on).

Close codes: 4401 bad token, 4404 unknown database, 4400 not a ready control database or bad
settings, 4429 (or HTTP 429) too many live sessions (``SEGUE_MAX_SESSIONS``), 1009 a message over
64 KiB. Messages are handled in order, one at a time, in a worker thread (never in the event loop).
"""

from __future__ import annotations

import contextlib
import json
from typing import Annotated, Any

import anyio
from fastapi import APIRouter, Query, WebSocket
from fastapi.websockets import WebSocketDisconnect
from pydantic import TypeAdapter, ValidationError

from engines.base import EngineError, LiveControlSession
from engines.registry import EngineClass, kind_class
from schemas.control import ControlSessionMessage, ControlSessionPath, ControlSessionPose
from workers.engine_cache import EngineCache
from workers.store import Store

from ..deps import EnginesDep, SessionQuotaDep, SettingsDep, StoreDep
from .events import WebSocketToken, live_session_database

router = APIRouter(prefix="/v1/sessions", tags=["sessions"])

_MESSAGES: TypeAdapter[Any] = TypeAdapter(ControlSessionMessage)
MAX_MESSAGE_CHARS = 65536
"""Longest client message (240 frames of 4 joints is about 30 KB)."""


def _follows(engine: EngineClass, db_id: str) -> None:
    engine.check_live_control(db_id)


def _open(
    engines: EngineCache, store: Store, db_id: str, kind: str, latency_s: float, k: float | None
) -> LiveControlSession:
    """A live control session on a database of ``kind`` (its engine loaded once per process)."""
    engine = engines.get(db_id, kind_class(kind), store.database_arrays)
    return engine.live_control(latency_s=latency_s, k=k)


def _handle(session: LiveControlSession, message: ControlSessionPose | ControlSessionPath) -> dict[str, Any]:
    if isinstance(message, ControlSessionPose):
        return session.push(message.frames)
    return session.push(message.points)


@router.websocket("/control")
async def control_session(
    websocket: WebSocket,
    store: StoreDep,
    settings: SettingsDep,
    engines: EnginesDep,
    quota: SessionQuotaDep,
    database: Annotated[str, Query(description="id of a ready control database")],
    latency_s: Annotated[float, Query(ge=0.5, le=5.0, description="fixed latency, seconds")] = 2.0,
    k: Annotated[float | None, Query(ge=0, le=1e6, description="continuity weight (seconds)")] = None,
    token: WebSocketToken = None,
) -> None:
    """Generate the target from a control streamed live (see the module doc for the protocol)."""
    async with live_session_database(websocket, settings, token, store, quota, database, _follows) as info:
        if info is None:
            return
        try:
            session = await anyio.to_thread.run_sync(_open, engines, store, database, info.kind, latency_s, k)
        except EngineError as exc:
            await websocket.close(code=4400, reason=str(exc)[:120])
            return
        await websocket.send_json(session.hello_message())
        await _run(websocket, session)


async def _run(websocket: WebSocket, session: LiveControlSession) -> None:
    """Read, validate and answer client messages in order until ``stop`` or the client leaves."""
    with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
        while True:
            text = await websocket.receive_text()
            if len(text) > MAX_MESSAGE_CHARS:
                await websocket.close(code=1009, reason="message too big")
                return
            try:
                message = _MESSAGES.validate_json(text)
            except ValidationError as exc:
                errors = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
                await websocket.send_json({"type": "error", "message": errors[:500] or "invalid message"})
                continue
            try:
                if isinstance(message, ControlSessionPose | ControlSessionPath):
                    reply = await anyio.to_thread.run_sync(_handle, session, message)
                else:
                    reply = await anyio.to_thread.run_sync(session.finish)
            except EngineError as exc:
                await websocket.send_json({"type": "error", "message": str(exc)})
                continue
            await websocket.send_text(json.dumps(reply, separators=(",", ":")))
            if not isinstance(message, ControlSessionPose | ControlSessionPath):
                await websocket.send_json({"type": "end", "frames": session.frame, "solves": session.solves})
                await websocket.close(code=1000)
                return
