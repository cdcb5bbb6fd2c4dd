"""Live sessions: ``WebSocket /v1/sessions/rhythm?database=<id>`` — a character dancing to beats
sent as they happen (the game-engine integration path of the rhythm engine).

Protocol (JSON text messages):

* client -> server: ``{"type": "beat"}`` (a music beat, now), ``{"type": "bpm", "bpm": 120}`` (the
  server generates beats from now on; a later ``beat`` re-phases them), ``{"type": "direction",
  "heading_deg": 90, "speed": 0.5}`` (steer from the next movement; omit both to dance freely),
  ``{"type": "stop"}``.
* server -> client: first ``{"type": "skeleton", "names", "parents", "offsets", "fps",
  "beats_per_movement", ...}``; then at every beat ``{"type": "frames", "start": i, "fps": f,
  "beat": k, "root": [[x, y, z], ...], "rotations": [[[x, y, z, w], ...], ...]}`` — the frames of
  the beat that just started (frame indices ``start ..``; the motion beat is the batch's first
  frame), so latency is at most one beat; ``{"type": "error", "message"}`` for a bad message (the
  session goes on); ``{"type": "end", "frames", "beats"}`` after ``stop``, then close 1000.

Close codes: 4401 bad token, 4404 unknown database, 4400 not a ready rhythm database, 4429 (or an
HTTP 429 refusal) too many live sessions of this principal (``SEGUE_MAX_SESSIONS``), 1009 a message
over 4096 characters. The inbox of client messages holds ``SEGUE_SESSION_INBOX`` messages; a client
sending faster than its beats are rendered is read no faster (backpressure). Synthesis
runs in a worker thread, never in the event loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from typing import Annotated, Any

import anyio
from fastapi import APIRouter, Query, WebSocket
from fastapi.websockets import WebSocketDisconnect
from pydantic import TypeAdapter, ValidationError

from engines.base import LiveSession
from engines.registry import EngineClass, kind_class
from schemas.rhythm import SessionBeat, SessionBpm, SessionDirection, SessionMessage, SessionStop
from workers.engine_cache import EngineCache
from workers.store import Store

from ..deps import EnginesDep, SessionQuotaDep, SettingsDep, StoreDep
from .events import WebSocketToken, live_session_database

router = APIRouter(prefix="/v1/sessions", tags=["sessions"])

_MESSAGES: TypeAdapter[Any] = TypeAdapter(SessionMessage)
MAX_MESSAGE_CHARS = 4096
"""Longest client message (every valid one is well under 200 characters)."""


def _dances(engine: EngineClass, db_id: str) -> None:
    engine.check_live_session(db_id)


def _open_session(
    engines: EngineCache, store: Store, db_id: str, kind: str, seed: int, fps: float | None, accent: float
) -> tuple[LiveSession, dict[str, Any]]:
    """A live session on a database (its engine loaded once per process) and its first message."""
    engine = engines.get(db_id, kind_class(kind), store.database_arrays)
    session = engine.live_session(seed=seed, fps=fps, accent=accent)
    return session, session.skeleton_message()


async def _reader(websocket: WebSocket, inbox: asyncio.Queue[str | None], limit: int) -> None:
    """Client messages into the bounded inbox; a text over ``limit`` bytes ends the session."""
    with contextlib.suppress(WebSocketDisconnect, RuntimeError):
        while True:
            text = await websocket.receive_text()
            if len(text) > limit:
                with contextlib.suppress(RuntimeError):
                    await websocket.close(code=1009, reason="message too big")
                break
            await inbox.put(text)  # waits while the inbox is full: the client is read no faster
    await inbox.put(None)


@router.websocket("/rhythm")
async def rhythm_session(
    websocket: WebSocket,
    store: StoreDep,
    settings: SettingsDep,
    engines: EnginesDep,
    quota: SessionQuotaDep,
    database: Annotated[str, Query(description="id of a ready rhythm database")],
    seed: Annotated[int, Query(ge=0, le=2**32 - 1)] = 0,
    fps: Annotated[float | None, Query(gt=0, le=240)] = None,
    accent: Annotated[float, Query(ge=0, le=0.9)] = 0.6,
    token: WebSocketToken = None,
) -> None:
    """Dance to beats sent live (see the module doc for the message format)."""
    async with live_session_database(websocket, settings, token, store, quota, database, _dances) as info:
        if info is None:
            return
        dancer, skeleton = await anyio.to_thread.run_sync(
            _open_session, engines, store, database, info.kind, seed, fps, accent
        )
        await websocket.send_json(skeleton)
        await _Session(websocket, dancer, settings.session_inbox).run()


class _Session:
    """The beat clock and message loop of one socket."""

    def __init__(self, websocket: WebSocket, dancer: LiveSession, inbox_size: int = 64) -> None:
        self.websocket, self.dancer = websocket, dancer
        self.inbox_size = inbox_size
        self.period = dancer.period_s
        self.auto_next: float | None = None  # loop time of the next generated beat (bpm mode)
        self.last_beat: float | None = None

    async def beat(self, now: float) -> None:
        period = self.period
        if self.auto_next is None and self.last_beat is not None and 0.2 <= now - self.last_beat <= 3.0:
            period = now - self.last_beat  # manual beats: the last interval predicts the next
        self.last_beat = now
        msg = await anyio.to_thread.run_sync(self.dancer.beat, period)
        await self.websocket.send_text(json.dumps(msg, separators=(",", ":")))

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        inbox: asyncio.Queue[str | None] = asyncio.Queue(self.inbox_size)
        reader = asyncio.create_task(_reader(self.websocket, inbox, MAX_MESSAGE_CHARS))
        try:
            while True:
                timeout = None if self.auto_next is None else max(0.0, self.auto_next - loop.time())
                try:
                    text = await asyncio.wait_for(inbox.get(), timeout)
                except TimeoutError:
                    self.auto_next = (self.auto_next or loop.time()) + self.period
                    await self.beat(loop.time())
                    continue
                if text is None:
                    return  # the client went away
                try:
                    message = _MESSAGES.validate_json(text)
                except ValidationError as exc:
                    errors = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
                    await self.websocket.send_json({"type": "error", "message": errors or "invalid message"})
                    continue
                now = loop.time()
                if isinstance(message, SessionBeat):
                    if self.auto_next is not None:
                        self.auto_next = now + self.period  # re-phase the generated beats
                    await self.beat(now)
                elif isinstance(message, SessionBpm):
                    self.period = 60.0 / message.bpm
                    self.auto_next = now + self.period
                    await self.beat(now)
                elif isinstance(message, SessionDirection):
                    self.dancer.steer(message.heading_deg, message.speed)
                elif isinstance(message, SessionStop):
                    await self.websocket.send_json(
                        {"type": "end", "frames": self.dancer.frame, "beats": self.dancer.beats}
                    )
                    await self.websocket.close(code=1000)
                    return
        except (WebSocketDisconnect, RuntimeError, OSError):
            return
        finally:
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await reader
