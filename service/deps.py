"""Dependencies: the settings, store, backend and metrics of the running app, and bearer auth.

Routes take them as ``Annotated`` aliases (``store: StoreDep``); tests override
:func:`app_settings` (``app.dependency_overrides[app_settings] = lambda: other``) to change what
routes see (e.g. switch auth on) without restarting the backend.
"""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import Depends
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.requests import HTTPConnection

from workers.backend import JobBackend
from workers.store import Store

from .errors import ApiError, unauthorized
from .metrics import Metrics
from .settings import Settings


def app_settings(conn: HTTPConnection) -> Settings:
    """The settings the app was created with."""
    settings: Settings = conn.app.state.settings
    return settings


def app_store(conn: HTTPConnection) -> Store:
    """The durable store."""
    store: Store = conn.app.state.store
    return store


def app_backend(conn: HTTPConnection) -> JobBackend:
    """The job backend (503 while the app is starting or stopping)."""
    backend: JobBackend | None = getattr(conn.app.state, "backend", None)
    if backend is None:
        raise ApiError(
            503, "unavailable", "the job backend is not running (the service is starting or stopping)"
        )
    return backend


def app_metrics(conn: HTTPConnection) -> Metrics:
    """The process's metrics."""
    metrics: Metrics = conn.app.state.metrics
    return metrics


SettingsDep = Annotated[Settings, Depends(app_settings)]
StoreDep = Annotated[Store, Depends(app_store)]
BackendDep = Annotated[JobBackend, Depends(app_backend)]
MetricsDep = Annotated[Metrics, Depends(app_metrics)]

_bearer = HTTPBearer(auto_error=False, description="required for writes when SEGUE_API_TOKENS is set")


def token_problem(settings: Settings, token: str | None) -> ApiError | None:
    """Why ``token`` does not authorize a write (None when it does, or when auth is off)."""
    if not settings.auth_enabled:
        return None
    if not token:
        return unauthorized(
            "this server requires a bearer token for writes: send 'Authorization: Bearer <token>'"
        )
    if not any(hmac.compare_digest(token.encode(), t.encode()) for t in settings.api_tokens):
        return unauthorized("the bearer token is not valid", invalid=True)
    return None


def require_token(
    settings: SettingsDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> None:
    """Writes: a valid ``Authorization: Bearer`` token when ``SEGUE_API_TOKENS`` is set (else 401)."""
    token = credentials.credentials if credentials is not None else None
    problem = token_problem(settings, token)
    if problem is not None:
        raise problem


AuthDep = Depends(require_token)
"""Add to a write route: ``@router.post(..., dependencies=[AuthDep])``."""


def bearer_token(conn: HTTPConnection, query_token: str | None = None) -> str | None:
    """The token of a connection: the ``Authorization: Bearer`` header, else ``?token=``."""
    header = conn.headers.get("authorization", "")
    scheme, _, value = header.partition(" ")
    if scheme.lower() == "bearer" and value.strip():
        return value.strip()
    return query_token or None
