"""Request guards that sit in front of every route (pure ASGI middleware, HTTP and WebSocket).

* :class:`HostOriginGuard` — DNS rebinding and cross-site requests. The ``Host`` header must name one
  of ``SEGUE_ALLOWED_HOSTS`` (default ``127.0.0.1``, ``localhost``, ``::1``): a page on
  ``evil.example`` whose name was re-pointed at 127.0.0.1 still sends ``Host: evil.example`` and is
  refused (400 ``invalid_host``). A request that carries an ``Origin`` header (browsers send it on
  every cross-origin request and on every POST and WebSocket) must come from the server's own origin
  (scheme, host and port of the request) or from ``SEGUE_CORS_ORIGINS``; anything else, including
  ``Origin: null``, is 403 ``cross_origin``. Clients that are not browsers send no ``Origin`` and
  pass. The page served at ``/`` is same-origin, so it passes too.
* :class:`CatchAll` — an unexpected exception becomes the contract's 500 JSON body *without*
  dropping the keep-alive connection (Starlette's outermost error middleware answers, then re-raises,
  and the server closes the connection).

Hand-written because Starlette's ``TrustedHostMiddleware`` covers only the first half of the first
guard, answers in plain text (not the error JSON of the contract) and does not guard WebSockets with
a proper refusal.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from urllib.parse import urlsplit

from starlette.datastructures import Headers
from starlette.requests import Request
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .errors import disconnected, error_body, error_response, quiet_response

log = logging.getLogger("segue.service")

DEFAULT_PORTS = {"http": 80, "https": 443, "ws": 80, "wss": 443}


def split_host(host: str) -> tuple[str, int | None]:
    """``"[::1]:8000"`` -> ``("::1", 8000)``; ``"localhost"`` -> ``("localhost", None)`` (lower case)."""
    host = host.strip().lower()
    if host.startswith("["):
        name, _, rest = host[1:].partition("]")
        port = rest[1:] if rest.startswith(":") else ""
    else:
        name, _, port = host.partition(":") if host.count(":") == 1 else (host, "", "")
    return name, int(port) if port.isdigit() else None


def normalize_origin(origin: str) -> str | None:
    """``scheme://host:port`` with the default port made explicit (None when it is not a URL)."""
    parts = urlsplit(origin.strip().lower())
    if parts.scheme not in ("http", "https") or not parts.hostname:
        return None
    try:
        port = parts.port or DEFAULT_PORTS[parts.scheme]
    except ValueError:
        return None
    host = f"[{parts.hostname}]" if ":" in parts.hostname else parts.hostname
    return f"{parts.scheme}://{host}:{port}"


class HostOriginGuard:
    """Refuse requests to an unexpected Host or from a foreign Origin (see the module docstring)."""

    def __init__(self, app: ASGIApp, allowed_hosts: Iterable[str], cors_origins: Iterable[str] = ()) -> None:
        self.app = app
        hosts = {h.strip().lower().strip("[]") for h in allowed_hosts if h.strip()}
        self.any_host = "*" in hosts
        self.hosts = hosts - {"*"}
        self.origins = {o for o in (normalize_origin(x) for x in cors_origins) if o is not None}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = Headers(scope=scope)
        problem = self._problem(scope, headers)
        if problem is None:
            await self.app(scope, receive, send)
            return
        status, code, message = problem
        if scope["type"] == "http":
            await error_response(status, code, message)(scope, receive, send)
            return
        await self._refuse_websocket(scope, receive, send, status, code, message)

    def _problem(self, scope: Scope, headers: Headers) -> tuple[int, str, str] | None:
        host_header = headers.get("host", "")
        name, port = split_host(host_header)
        if not self.any_host and name not in self.hosts:
            return (
                400,
                "invalid_host",
                f"this server does not answer to the host name {name!r} (SEGUE_ALLOWED_HOSTS)",
            )
        origin = headers.get("origin")
        if origin is None:
            return None
        normalized = normalize_origin(origin)
        if normalized is not None and normalized in self.origins:
            return None
        scheme = {"ws": "http", "wss": "https"}.get(scope.get("scheme", "http"), scope.get("scheme", "http"))
        if normalized is not None and host_header:
            own = normalize_origin(f"{scheme}://{host_header}")
            if normalized == own:
                return None
        return (
            403,
            "cross_origin",
            f"requests from the origin {origin!r} are not allowed (same origin or SEGUE_CORS_ORIGINS only)",
        )

    @staticmethod
    async def _refuse_websocket(
        scope: Scope, receive: Receive, send: Send, status: int, code: str, message: str
    ) -> None:
        await receive()  # websocket.connect
        if "websocket.http.response" in scope.get("extensions", {}):
            response = error_response(status, code, message)
            await send(
                {
                    "type": "websocket.http.response.start",
                    "status": status,
                    "headers": response.raw_headers,
                }
            )
            await send({"type": "websocket.http.response.body", "body": response.body})
            return
        await send({"type": "websocket.close", "code": 4000 + status, "reason": message[:120]})


class CatchAll:
    """Answer an unhandled exception with the contract's 500 body and keep the connection."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def tracked(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, receive, tracked)
        except Exception as exc:
            quiet = quiet_response(Request(scope), exc)
            if quiet is not None and not started:
                await quiet(scope, receive, send)
                return
            if quiet is not None and disconnected(exc):
                return  # the client left mid-answer: nothing to say, nobody to say it to
            log.exception("unhandled error on %s %s", scope.get("method"), scope.get("path"), exc_info=exc)
            if started:
                raise  # half a response is out: only closing the connection can say so
            body = error_body("internal", f"internal error ({type(exc).__name__}); see the server log")
            await error_response(500, body["error"]["code"], body["error"]["message"])(scope, receive, send)
