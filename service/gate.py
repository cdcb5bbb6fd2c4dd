"""The principal's share of the server's connections, kept before the app reads a request's body
(the ASGI gate ``segue serve`` wraps the app in; the per-connection limits are
:mod:`service.server`'s).

With tokens (``SEGUE_API_TOKENS``), each request in progress and each open WebSocket counts
towards its principal (the token's, from the ``Authorization`` header, or a WebSocket's
``?token=``). One beyond ``SEGUE_MAX_CONNECTIONS_PER_PRINCIPAL`` is answered ``503``
``too_many_connections`` with ``Retry-After`` and its connection closed, before its body is read,
so one token holder cannot take every connection from the others. A request carrying a body
without a valid token is answered ``401`` (and closed) before its body is read, as the app would
answer once it had read it; a request without a body is left to the app (which answers 401 on
``/v1`` routes itself, with the same message).
"""

from __future__ import annotations

import json
from collections import Counter
from typing import Any

from starlette.requests import HTTPConnection
from starlette.types import ASGIApp, Receive, Scope, Send

from workers.settings import Settings

from .deps import authenticate, bearer_token
from .errors import ApiError, error_body
from .server import SHARE_RETRY_AFTER_S


def has_body(scope: Scope) -> bool:
    """True when an HTTP request announces a body (a non-zero ``Content-Length``, or chunks)."""
    for name, value in scope.get("headers", ()):
        if name == b"content-length":
            return value.strip() not in (b"", b"0")
        if name == b"transfer-encoding":
            return True
    return False


class PrincipalGate:
    """ASGI middleware counting each principal's requests in progress and open WebSockets (see the
    module docstring); without tokens it only passes requests on."""

    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app, self.settings = app, settings
        self.limit = settings.max_connections_per_principal
        self.busy: Counter[str] = Counter()
        """Requests in progress and open WebSockets per principal."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket") or not self.settings.auth_enabled:
            await self.app(scope, receive, send)
            return
        conn = HTTPConnection(scope)
        query_token = conn.query_params.get("token") if kind == "websocket" else None
        caller = authenticate(self.settings, bearer_token(conn, query_token))
        if isinstance(caller, ApiError):
            if kind == "http" and has_body(scope):
                await refuse(scope, receive, send, caller)
            else:
                await self.app(scope, receive, send)
            return
        name = caller.name
        if self.busy[name] >= self.limit:
            await refuse(scope, receive, send, self.too_many())
            return
        self.busy[name] += 1
        try:
            await self.app(scope, receive, send)
        finally:
            self.busy[name] -= 1
            if self.busy[name] <= 0:
                del self.busy[name]

    def too_many(self) -> ApiError:
        """The 503 for a principal at its share."""
        return ApiError(
            503,
            "too_many_connections",
            f"you have {self.limit} requests and WebSockets open at once "
            "(SEGUE_MAX_CONNECTIONS_PER_PRINCIPAL); wait for some to end",
            {"limit": self.limit},
            headers={"Retry-After": str(SHARE_RETRY_AFTER_S)},
        )


async def refuse(scope: Scope, receive: Receive, send: Send, error: ApiError) -> None:
    """Answer ``error`` without reading a body: an HTTP response that closes the connection, or a
    WebSocket handshake's denial (a close with 1013 "try again later" when the server cannot send a
    denial response)."""
    body = json.dumps(error_body(error.code, error.message, error.details)).encode()
    headers: list[tuple[bytes, bytes]] = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
        *((k.lower().encode(), v.encode()) for k, v in (error.headers or {}).items()),
    ]
    start: dict[str, Any]
    if scope["type"] == "http":
        start = {"type": "http.response.start", "status": error.status}
        start["headers"] = [*headers, (b"connection", b"close")]
        await send(start)
        await send({"type": "http.response.body", "body": body})
        return
    await receive()  # websocket.connect
    if "websocket.http.response" in scope.get("extensions", {}):
        start = {"type": "websocket.http.response.start", "status": error.status, "headers": headers}
        await send(start)
        await send({"type": "websocket.http.response.body", "body": body})
    else:
        await send({"type": "websocket.close", "code": 1013, "reason": error.message[:120]})
