"""Serving the app with uvicorn, with limits on what a client may hold: slow-loris connections are
closed and open connections are bounded, in all and per client address and per principal, so one
client cannot lock the others out.

uvicorn (0.3x) keeps a connection that never completes its request for ever: its keep-alive timer
only runs after a response, and any byte received cancels it, so a client dripping one byte every
few seconds holds a socket (and a file descriptor) as long as it likes; thousands of those reached
the process's open-files limit (``EMFILE``), or the connection limit, after which nobody could
connect. uvicorn has no setting for any of this, so :class:`GuardedH11Protocol` extends its h11
protocol (passed as ``uvicorn.run(http=...)``, the documented way to choose a protocol class):

- **request timeout** (``SEGUE_REQUEST_TIMEOUT_S``): a connection that has not sent a whole
  request's headers within that time of connecting (or of its previous response) is closed, and so
  is one that pauses longer than that while sending a body;
- **request deadline** (``SEGUE_REQUEST_DEADLINE_S``): a request's headers and body must have
  arrived within that time of its start, however steadily they flow;
- **minimum body rate** (``SEGUE_MIN_BODY_RATE``, ``SEGUE_BODY_RATE_GRACE_S``): ``t`` seconds into
  a body, ``rate x (t - grace)`` bytes must have arrived (a body trickling a byte every few seconds
  is cut after the grace). Time the server itself stops reading (flow control: the app has not read
  what arrived) restarts the measure;
- a request cut by one of these gets ``408`` (when nothing was answered yet) and its connection is
  closed; once a request is in, its handler (a long-poll, a WebSocket, a long download) runs as long
  as it needs;
- **connection limits** (``SEGUE_MAX_CONNECTIONS``, ``SEGUE_MAX_CONNECTIONS_PER_ADDRESS``): a
  connection beyond the server's total, or beyond its client address's share, gets ``503``
  ``too_many_connections`` with ``Retry-After`` and is closed at once (WebSockets count, until they
  close); the soft open-files limit is raised (up to the hard one) to fit the total plus room for
  the store, Redis and the engine processes.

The principal's share (``SEGUE_MAX_CONNECTIONS_PER_PRINCIPAL``) needs the request's token, so it is
kept one level up, by the ASGI gate of :mod:`service.gate` (before the app reads a body).
"""

from __future__ import annotations

import asyncio
import logging
import resource
import time
from collections import Counter
from typing import Any, ClassVar

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from workers.settings import Settings

log = logging.getLogger("segue.server")


def canned(status: str, code: str, message: str, retry_after: int | None = None) -> bytes:
    """A complete ``connection: close`` JSON error response (the client reads it, then EOF)."""
    body = b'{"error":{"code":"%s","message":"%s"}}' % (code.encode(), message.encode())
    retry = b"retry-after: %d\r\n" % retry_after if retry_after is not None else b""
    return (
        b"HTTP/1.1 %s\r\ncontent-type: application/json\r\n%sconnection: close\r\n"
        b"content-length: %d\r\n\r\n%s" % (status.encode(), retry, len(body), body)
    )


SHARE_RETRY_AFTER_S = 5
"""The ``Retry-After`` of a refusal over a client's share (an address's, a principal's): longer than
over the server's total, since that client holds many connections already."""
BUSY = canned(
    "503 Service Unavailable",
    "too_many_connections",
    "the server has too many open connections; try again",
    retry_after=1,
)
"""The answer to a connection over the server's total."""
BUSY_ADDRESS = canned(
    "503 Service Unavailable",
    "too_many_connections",
    "too many open connections from your address (SEGUE_MAX_CONNECTIONS_PER_ADDRESS); close some "
    "or try again",
    retry_after=SHARE_RETRY_AFTER_S,
)
"""The answer to a connection over its client address's share."""
TIMED_OUT = canned(
    "408 Request Timeout",
    "request_timeout",
    "the request did not arrive in time (SEGUE_REQUEST_TIMEOUT_S, SEGUE_REQUEST_DEADLINE_S, "
    "SEGUE_MIN_BODY_RATE); the connection is closed",
)
"""The answer to a request that was too slow to arrive."""

FD_HEADROOM = 1024
"""Open files kept beyond the connection limit (store files, Redis, pipes to engine processes)."""


class GuardedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with request timeouts and connection limits (module docstring);
    :func:`guarded_protocol` makes a subclass with the settings' values (one per server: the
    per-address counts are a class attribute of it)."""

    request_timeout_s: float = 30.0
    request_deadline_s: float = 600.0
    min_body_rate: float = 1024.0
    body_rate_grace_s: float = 10.0
    max_connections: int = 4096
    max_per_address: int = 512
    per_address: ClassVar[Counter[str]] = Counter()
    _rejected = 0
    _next_warning = 0.0

    _timer: asyncio.TimerHandle | None = None
    _address: str | None = None
    _request_start: float | None = None  # the current request's headers are awaited since
    _request_bytes = 0  # bytes of the current request received
    _idle_until = 0.0  # headers: the request timeout; a body: its pause limit
    _body_start: float | None = None  # the body is measured since (restarted after a server pause)
    _body_bytes = 0  # body bytes received since _body_start
    _upgraded = False  # a WebSocket has the connection: its request is whole, no limit of ours applies

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        cls = type(self)
        if len(self.connections) > self.max_connections:
            self._reject(transport, BUSY, f"{len(self.connections)} open connections")
            return
        address = self.client[0] if self.client else ""
        if cls.per_address[address] >= self.max_per_address:
            self._reject(transport, BUSY_ADDRESS, f"{cls.per_address[address]} connections from {address}")
            return
        cls.per_address[address] += 1
        self._address = address
        self._follow_state()

    def _reject(self, transport: asyncio.Transport, answer: bytes, why: str) -> None:
        cls = type(self)
        cls._rejected += 1
        now = time.monotonic()
        if now >= cls._next_warning:  # once every 10 s, not once per connection
            cls._next_warning = now + 10.0
            log.warning(
                "%s (limits: %d in all, %d per address): refusing new connections (%d so far)",
                why,
                self.max_connections,
                self.max_per_address,
                cls._rejected,
            )
        self.connections.discard(self)
        transport.write(answer)
        transport.close()

    def _release_address(self) -> None:
        if self._address is not None:
            counts = type(self).per_address
            counts[self._address] -= 1
            if counts[self._address] <= 0:
                del counts[self._address]
            self._address = None

    def data_received(self, data: bytes) -> None:
        in_body = self.conn.their_state is h11.SEND_BODY
        self._request_bytes += len(data)
        super().data_received(data)
        self._follow_state()
        if in_body or self.conn.their_state is h11.SEND_BODY:
            self._body_bytes += len(data)
            self._idle_until = self.loop.time() + self.request_timeout_s

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():
            self._follow_state()

    def handle_websocket_upgrade(self, event: h11.Request) -> None:
        self._upgraded = True
        self._cancel_timer()
        super().handle_websocket_upgrade(event)
        # the WebSocket protocol has the transport now: it keeps this address's slot until it closes
        websocket = self.transport.get_protocol()
        lost = websocket.connection_lost

        def connection_lost(exc: Exception | None) -> None:
            try:
                lost(exc)
            finally:
                self._release_address()

        websocket.connection_lost = connection_lost  # type: ignore[method-assign]

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel_timer()
        self._release_address()
        super().connection_lost(exc)

    # -- the deadlines ------------------------------------------------------------------------
    def _waiting_for_client(self) -> bool:
        """True while the client owes us bytes: a request's headers (no request in progress) or
        its body."""
        state = self.conn.their_state
        if state is h11.SEND_BODY:
            return True
        return state is h11.IDLE and (self.cycle is None or self.cycle.response_complete)

    def _follow_state(self) -> None:
        """After a connection, bytes or a response: start measuring a request whose headers are
        awaited, or its body; stop once the request is whole."""
        if self._upgraded or self.transport.is_closing():
            return
        now = self.loop.time()
        if not self._waiting_for_client():
            self._request_start = self._body_start = None
            self._cancel_timer()
            return
        if self._request_start is None:  # a new request's headers are awaited from now on
            self._request_start, self._request_bytes = now, 0
            self._idle_until = now + self.request_timeout_s
            self._schedule(now)
        if self.conn.their_state is h11.SEND_BODY and self._body_start is None:
            self._body_start, self._body_bytes = now, 0
            self._idle_until = now + self.request_timeout_s
            self._schedule(now)

    def _next_check(self, now: float) -> float:
        """When the current request may next be overdue (its limits as they stand at ``now``)."""
        assert self._request_start is not None
        due = min(self._idle_until, self._request_start + self.request_deadline_s)
        if self._body_start is not None and self.min_body_rate > 0:
            due = min(due, self._body_start + self.body_rate_grace_s + self._body_bytes / self.min_body_rate)
        return max(due, now + 0.01)

    def _schedule(self, now: float) -> None:
        self._cancel_timer()
        self._timer = self.loop.call_at(self._next_check(now), self._check)

    def _cancel_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _check(self) -> None:
        self._timer = None
        if self._upgraded or self.transport.is_closing() or not self._waiting_for_client():
            return
        if self._request_start is None:
            return
        now = self.loop.time()
        if self.flow.read_paused:  # the server is not reading: nothing the client can be blamed for
            self._request_start = now
            self._idle_until = now + self.request_timeout_s
            if self._body_start is not None:
                self._body_start, self._body_bytes = now, 0
            self._schedule(now)
            return
        why = None
        if now >= self._idle_until:
            why = f"no whole request headers, or a body pause, within {self.request_timeout_s:g} s"
        elif now >= self._request_start + self.request_deadline_s:
            why = f"the request took more than {self.request_deadline_s:g} s to arrive"
        elif self._body_start is not None and self.min_body_rate > 0:
            owed = self.min_body_rate * (now - self._body_start - self.body_rate_grace_s)
            if self._body_bytes < owed:
                why = f"its body arrives slower than {self.min_body_rate:g} bytes/s"
        if why is None:
            self._schedule(now)
        else:
            self._time_out(why)

    def _time_out(self, why: str) -> None:
        """408 (when nothing was answered for this request yet) and close the connection."""
        log.info(
            "closing the connection of %s: %s",
            f"{self.client[0]}:{self.client[1]}" if self.client else "a client",
            why,
        )
        cycle = self.cycle
        if self.conn.their_state is h11.SEND_BODY:  # the cycle is this request's
            answer = cycle is not None and not cycle.response_started
            if cycle is not None and not cycle.response_complete:
                cycle.disconnected = True  # the app's receive() says so, its sends go nowhere
                cycle.message_event.set()
        else:  # headers: the cycle, if any, was the previous request's
            answer = self._request_bytes > 0
        if answer:
            self.transport.write(TIMED_OUT)
        self.transport.close()


def guarded_protocol(settings: Settings, max_connections: int | None = None) -> type[GuardedH11Protocol]:
    """A :class:`GuardedH11Protocol` subclass with the settings' limits (one per server;
    ``max_connections`` overrides the settings' total)."""
    total = settings.max_connections if max_connections is None else max_connections
    attributes: dict[str, Any] = {
        "request_timeout_s": settings.request_timeout_s,
        "request_deadline_s": settings.request_deadline_s,
        "min_body_rate": float(settings.min_body_rate),
        "body_rate_grace_s": settings.body_rate_grace_s,
        "max_connections": total,
        "max_per_address": settings.max_connections_per_address,
        "per_address": Counter(),
    }
    return type("SegueH11Protocol", (GuardedH11Protocol,), attributes)


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
    # the listen queue holds a burst as large as the limit (refused clients coming back at once):
    # an overflowing queue drops new clients' SYNs, which their kernels resend only after 1 s, 3 s...
    backlog = max(2048, min(limit, 65535))
    return {"http": guarded_protocol(settings, limit), "timeout_keep_alive": 5, "backlog": backlog}


def guarded_app(app: Any, settings: Settings) -> Any:
    """``app`` behind the principal's share of connections (:class:`service.gate.PrincipalGate`)."""
    from .gate import PrincipalGate

    return PrincipalGate(app, settings)


def serve(app: Any, settings: Settings, host: str, port: int, log_level: str = "info") -> None:
    """Run ``app`` with uvicorn in this process until interrupted, with the limits above."""
    import uvicorn

    uvicorn.run(
        guarded_app(app, settings), host=host, port=port, log_level=log_level, **uvicorn_options(settings)
    )
