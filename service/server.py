"""Serving the app with uvicorn, with limits on what a client may hold: slow-loris connections are
closed and the number of open connections is bounded.

uvicorn (0.3x) keeps a connection that never completes its request for ever: its keep-alive timer
only runs after a response, and any byte received cancels it, so a client dripping one header byte
every few seconds holds a socket (and a file descriptor) as long as it likes; thousands of those
reached the process's open-files limit (``EMFILE``), after which nobody could connect. uvicorn has
no setting for either, so :class:`GuardedH11Protocol` extends its h11 protocol (passed as
``uvicorn.run(http=...)``, the documented way to choose a protocol class):

- **request timeout** (``SEGUE_REQUEST_TIMEOUT_S``): a connection that has not sent a whole
  request's headers within that time of connecting (or of its previous response) is closed, and so
  is one that pauses longer than that while sending a body (an upload still flowing is not cut);
  once a request is in, its handler (a WebSocket, a long download) runs as long as it needs;
- **connection limit** (``SEGUE_MAX_CONNECTIONS``): a connection beyond it gets ``503`` with
  ``Retry-After`` and is closed at once, and the soft open-files limit is raised (up to the hard
  one) to fit the limit plus room for the store, Redis and the engine processes.
"""

from __future__ import annotations

import asyncio
import logging
import resource
import time
from typing import Any

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from workers.settings import Settings

log = logging.getLogger("segue.server")

_BUSY_BODY = (
    b'{"error":{"code":"too_many_connections",'
    b'"message":"the server has too many open connections; try again"}}'
)
BUSY = (
    b"HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\nretry-after: 1\r\n"
    b"connection: close\r\ncontent-length: %d\r\n\r\n%s" % (len(_BUSY_BODY), _BUSY_BODY)
)
"""The answer to a connection over the limit (a complete response: the client reads it, then EOF)."""

FD_HEADROOM = 1024
"""Open files kept beyond the connection limit (store files, Redis, pipes to engine processes)."""


class GuardedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with a request timeout and a connection limit (module docstring);
    :func:`guarded_protocol` makes a subclass with the settings' values."""

    request_timeout_s: float = 30.0
    max_connections: int = 4096
    _rejected = 0
    _next_warning = 0.0
    _deadline: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        if len(self.connections) > self.max_connections:
            self._reject(transport)
            return
        self._arm()

    def _reject(self, transport: asyncio.Transport) -> None:
        cls = type(self)
        cls._rejected += 1
        now = time.monotonic()
        if now >= cls._next_warning:  # once every 10 s, not once per connection
            cls._next_warning = now + 10.0
            log.warning(
                "%d open connections (limit %d): refusing new ones (%d so far)",
                len(self.connections),
                self.max_connections,
                cls._rejected,
            )
        self.connections.discard(self)
        transport.write(BUSY)
        transport.close()

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        self._follow_state()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():
            self._follow_state()

    def handle_websocket_upgrade(self, event: h11.Request) -> None:
        self._disarm()
        super().handle_websocket_upgrade(event)

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)

    # -- the deadline -----------------------------------------------------------------------
    def _waiting_for_client(self) -> bool:
        """True while the client owes us bytes: a request's headers (no request in progress) or
        its body."""
        state = self.conn.their_state
        if state is h11.SEND_BODY:
            return True
        return state is h11.IDLE and (self.cycle is None or self.cycle.response_complete)

    def _follow_state(self) -> None:
        """After bytes arrived or a response ended: headers keep the deadline they had (a total),
        a body that moves gets a fresh one (an idle timeout), a whole request has none."""
        if self.conn.their_state is h11.SEND_BODY:
            self._arm()
        elif self._waiting_for_client():
            if self._deadline is None:
                self._arm()
        else:
            self._disarm()

    def _arm(self) -> None:
        self._disarm()
        self._deadline = self.loop.call_later(self.request_timeout_s, self._expire)

    def _disarm(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _expire(self) -> None:
        self._deadline = None
        if self.transport.is_closing() or not self._waiting_for_client():
            return
        log.info(
            "closing the connection of %s: no whole request within %g s",
            f"{self.client[0]}:{self.client[1]}" if self.client else "a client",
            self.request_timeout_s,
        )
        self.transport.close()


def guarded_protocol(request_timeout_s: float, max_connections: int) -> type[GuardedH11Protocol]:
    """A :class:`GuardedH11Protocol` subclass with these limits (one per server)."""
    return type(
        "SegueH11Protocol",
        (GuardedH11Protocol,),
        {"request_timeout_s": request_timeout_s, "max_connections": max_connections},
    )


def raise_open_files_limit(wanted: int) -> int:
    """Raise the soft ``RLIMIT_NOFILE`` to ``wanted`` (at most the hard limit); returns the soft
    limit now in force."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
    if target > soft:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
            soft = target
        except (ValueError, OSError) as exc:
            log.warning("could not raise the open-files limit to %d: %s", target, exc)
    return soft


def uvicorn_options(settings: Settings) -> dict[str, Any]:
    """The uvicorn options of ``segue serve``: the guarded protocol with the settings' limits (the
    connection limit lowered to what the open-files limit allows)."""
    soft = raise_open_files_limit(settings.max_connections + FD_HEADROOM)
    limit = settings.max_connections
    if soft - FD_HEADROOM < limit:
        limit = max(soft - FD_HEADROOM, 64)
        log.warning(
            "the open-files limit is %d: serving at most %d connections (SEGUE_MAX_CONNECTIONS=%d)",
            soft,
            limit,
            settings.max_connections,
        )
    return {"http": guarded_protocol(settings.request_timeout_s, limit), "timeout_keep_alive": 5}


def serve(app: Any, settings: Settings, host: str, port: int, log_level: str = "info") -> None:
    """Run ``app`` with uvicorn in this process until interrupted, with the limits above."""
    import uvicorn

    uvicorn.run(app, host=host, port=port, log_level=log_level, **uvicorn_options(settings))
