"""Dependencies: the settings, store, backend and metrics of the running app, and the caller.

Tokens name principals (``SEGUE_API_TOKENS="alice:t1,bob:t2"``); :class:`Principal` is who calls.
Without tokens every caller is the one local user (:data:`LOCAL`), who may do everything.

Routes take them as ``Annotated`` aliases (``store: StoreDep``); tests override
:func:`app_settings` (``app.dependency_overrides[app_settings] = lambda: other``) to change what
routes see (e.g. switch auth on) without restarting the backend.
"""

from __future__ import annotations

import hashlib
import hmac
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, TypeVar

import anyio
from fastapi import Depends
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.requests import HTTPConnection

from workers.backend import JobBackend
from workers.engine_cache import EngineCache
from workers.store import Store

from .errors import ApiError, unauthorized
from .limits import JobQuota, SessionQuota
from .metrics import Metrics
from .settings import Settings

State = TypeVar("State")


def from_state(name: str, kind: type[State]) -> Callable[[HTTPConnection], State]:
    """A dependency giving ``app.state.<name>`` (set by :func:`service.app.create_app`) as a ``kind``."""

    def dependency(conn: HTTPConnection) -> State:
        value: State = getattr(conn.app.state, name)
        return value

    dependency.__name__ = dependency.__qualname__ = f"app_{name}"
    dependency.__doc__ = f"The app's {name} (``app.state.{name}``)."
    return dependency


app_settings = from_state("settings", Settings)
"""The settings the app was created with (tests override this dependency)."""
app_store = from_state("store", Store)
app_metrics = from_state("metrics", Metrics)
app_job_quota = from_state("job_quota", JobQuota)
"""Unfinished jobs per principal (``SEGUE_MAX_QUEUED_JOBS``)."""
app_session_quota = from_state("session_quota", SessionQuota)
"""Live sessions per principal (``SEGUE_MAX_SESSIONS``)."""
app_engines = from_state("engines", EngineCache)
"""The engines this process has loaded for live sessions (the only engine work it does itself, in
worker threads)."""


def app_backend(conn: HTTPConnection) -> JobBackend:
    """The job backend (503 while the app is starting or stopping)."""
    backend: JobBackend | None = getattr(conn.app.state, "backend", None)
    if backend is None:
        raise ApiError(
            503, "unavailable", "the job backend is not running (the service is starting or stopping)"
        )
    return backend


def parse_limiter(conn: HTTPConnection, settings: Settings) -> anyio.CapacityLimiter:
    """The app's bound on concurrent body parses (``SEGUE_MAX_PARSES``; made on first use, one per
    app, since it belongs to the running event loop)."""
    limiter: anyio.CapacityLimiter | None = getattr(conn.app.state, "parse_limiter", None)
    if limiter is None:
        limiter = anyio.CapacityLimiter(settings.max_parses)
        conn.app.state.parse_limiter = limiter
    return limiter


def app_parse_limiter(
    conn: HTTPConnection, settings: Annotated[Settings, Depends(app_settings)]
) -> anyio.CapacityLimiter:
    """:func:`parse_limiter` as a dependency."""
    return parse_limiter(conn, settings)


SettingsDep = Annotated[Settings, Depends(app_settings)]
StoreDep = Annotated[Store, Depends(app_store)]
BackendDep = Annotated[JobBackend, Depends(app_backend)]
MetricsDep = Annotated[Metrics, Depends(app_metrics)]
JobQuotaDep = Annotated[JobQuota, Depends(app_job_quota)]
SessionQuotaDep = Annotated[SessionQuota, Depends(app_session_quota)]
EnginesDep = Annotated[EngineCache, Depends(app_engines)]
ParseLimiterDep = Annotated[anyio.CapacityLimiter, Depends(app_parse_limiter)]

_bearer = HTTPBearer(auto_error=False, description="required on every /v1 route when SEGUE_API_TOKENS is set")

LOCAL = "local"
"""The principal of a server without tokens (a single-user tool): it owns and may do everything."""


@dataclass(frozen=True, slots=True)
class Principal:
    """Who is calling: the name a token maps to (``SEGUE_API_TOKENS``), and whether it is an admin."""

    name: str
    admin: bool = False

    def may(self, owners: set[str] | str | None) -> bool:
        """True when the principal may read or change a thing held by ``owners`` (an admin always)."""
        if self.admin:
            return True
        if isinstance(owners, str):
            return owners == self.name
        return owners is not None and self.name in owners


def principal_of_token(entry: str) -> tuple[str, str]:
    """``"alice:s3cret"`` -> ``("alice", "s3cret")``; a bare token is named by its hash."""
    name, sep, token = entry.partition(":")
    if sep and name.strip() and token:
        return name.strip(), token
    return "token-" + hashlib.sha256(entry.encode()).hexdigest()[:8], entry


def token_table(settings: Settings) -> list[tuple[str, str]]:
    """(principal, token) for every configured token."""
    return [principal_of_token(entry) for entry in settings.api_tokens]


def authenticate(settings: Settings, token: str | None) -> Principal | ApiError:
    """The principal a token names, or the 401 to answer (no tokens configured: :data:`LOCAL`)."""
    if not settings.auth_enabled:
        return Principal(LOCAL, admin=True)
    if not token:
        return unauthorized("this server requires a bearer token: send 'Authorization: Bearer <token>'")
    found = None
    for name, known in token_table(settings):
        if hmac.compare_digest(token.encode(), known.encode()):
            found = name  # no early exit: the time taken does not depend on which token matched
    if found is None:
        return unauthorized("the bearer token is not valid", invalid=True)
    return Principal(found, admin=found in settings.admins)


def token_problem(settings: Settings, token: str | None) -> ApiError | None:
    """Why ``token`` is refused (None when it is valid, or when auth is off)."""
    result = authenticate(settings, token)
    return result if isinstance(result, ApiError) else None


def current_principal(
    conn: HTTPConnection,
    settings: SettingsDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> Principal:
    """The caller (401 without a valid ``Authorization: Bearer`` token when tokens are set).

    ``?token=`` is accepted on WebSockets only (browsers cannot set headers there); a token in the
    query of another request would end up in access logs, so it is refused with a message saying so."""
    token = credentials.credentials if credentials is not None else None
    if token is None and settings.auth_enabled and conn.query_params.get("token"):
        raise unauthorized(
            "pass the token as 'Authorization: Bearer <token>'; ?token= is accepted on WebSockets only"
        )
    result = authenticate(settings, token)
    if isinstance(result, ApiError):
        raise result
    return result


PrincipalDep = Annotated[Principal, Depends(current_principal)]
AuthDep = Depends(current_principal)
"""Add to a route that needs a caller but not its name: ``dependencies=[AuthDep]``."""


def websocket_principal(
    conn: HTTPConnection, settings: Settings, query_token: str | None
) -> Principal | ApiError:
    """The caller of a WebSocket: the ``Authorization`` header, else ``?token=``."""
    return authenticate(settings, bearer_token(conn, query_token))


def bearer_token(conn: HTTPConnection, query_token: str | None = None) -> str | None:
    """The token of a connection: the ``Authorization: Bearer`` header, else ``?token=``."""
    header = conn.headers.get("authorization", "")
    scheme, _, value = header.partition(" ")
    if scheme.lower() == "bearer" and value.strip():
        return value.strip()
    return query_token or None
