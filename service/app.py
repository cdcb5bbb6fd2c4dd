"""The Segue HTTP API: ``create_app(settings)`` builds the FastAPI app; ``run`` serves it.

The lifespan loads engine plugins, opens the :class:`~workers.store.Store` (every store call bounded
by ``SEGUE_STORE_TIMEOUT_S``: :mod:`workers.timed_objects`) and starts the job
backend: an :class:`~workers.embedded.EmbeddedBackend` (a local process pool) by default, or
``workers.redis_backend.RedisBackend`` when ``SEGUE_REDIS_URL`` is set. ``app.state`` holds the
settings, store, backend and metrics; routes reach them through :mod:`service.deps`.

Run it with ``segue serve``, :func:`run`, or ``uvicorn --factory service.app:create_app``.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.openapi.utils import get_openapi
from pydantic import TypeAdapter

from engines.registry import load_plugins, request_union, spec_union
from schemas.characters import CharacterRequest
from schemas.movement_graph import GraphEdits
from workers.backend import JobBackend
from workers.embedded import EmbeddedBackend
from workers.engine_cache import EngineCache
from workers.objects import S3Objects
from workers.store import Store
from workers.timed_objects import TimedObjects

from .errors import install_error_handlers
from .guard import CatchAll, HostOriginGuard
from .limits import JobQuota, SessionQuota
from .links import add_links
from .metrics import HttpMetricsMiddleware, Metrics, observe_terminal_events
from .routes import annotations as annotation_routes
from .routes import (
    characters,
    clips,
    control_sessions,
    databases,
    events,
    files,
    health,
    jobs,
    movement_graphs,
    sessions,
)
from .routes.annotations import Corrections
from .settings import Settings, get_settings
from .web import mount_web

log = logging.getLogger("segue.service")

API_VERSION = "1"

DESCRIPTION = """Motion synthesis by example. Upload BVH clips, build a database from them, submit
jobs against it and stream their events; download results as BVH, GLB, JSON frames or NPZ.

Every error body is `{"error": {"code", "message", "details"?}}`. JSON bodies must be sent as
`Content-Type: application/json` (at most `SEGUE_MAX_JSON_BYTES`, finite numbers only). When the server
sets `SEGUE_API_TOKENS`, every `/v1` request needs `Authorization: Bearer <token>` (WebSockets may pass
`?token=` instead); a token names a principal, which sees and changes only its own clips, files,
databases and jobs. Without tokens the server is a single-user tool for this machine."""


def make_backend(settings: Settings, store: Store) -> JobBackend:
    """The job backend the settings ask for (the Redis backend is imported only when used)."""
    if settings.redis_url:
        from workers.redis_backend import RedisBackend

        backend: JobBackend = RedisBackend(store, settings.redis_url, prefix=settings.redis_prefix)
        return backend
    return EmbeddedBackend.from_settings(store, settings)


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Start the store and the backend; stop the backend at shutdown."""
    settings: Settings = app.state.settings
    load_plugins(settings.engine_plugins)  # the engine processes get them from the settings too
    store = Store.from_settings(settings)
    if isinstance(store.objects, S3Objects):  # a stalled call's thread ends too (botocore's own timeout)
        store.objects.read_timeout_s = settings.store_timeout_s
    timed = TimedObjects(store.objects, settings.store_timeout_s)
    store.objects = timed  # no request waits on a stalled store past SEGUE_STORE_TIMEOUT_S
    backend = make_backend(settings, store)
    observe_terminal_events(backend.hub, app.state.metrics, since=time.time())
    app.state.job_quota = JobQuota(store, settings.max_queued_jobs)
    await backend.start()
    app.state.store, app.state.backend = store, backend
    log.info("segue API ready: data in %s, %s backend", settings.data_dir, type(backend).__name__)
    try:
        yield
    finally:
        app.state.backend = None
        # let callbacks of the last events run before the backend closes
        for _ in range(5):
            await asyncio.sleep(0)
        await backend.close()
        timed.close()


BODY_SCHEMAS: dict[str, Any] = {
    "JobRequest": request_union(),
    "DatabaseSpec": spec_union(),
    "LabelCorrections": Corrections,
    "GraphEdits": GraphEdits,
    "CharacterRequest": CharacterRequest,
}
"""Request bodies the routes parse themselves (:mod:`service.jsonbody`), documented as components."""


def _add_body_schemas(schema: dict[str, Any]) -> None:
    """Document the JSON bodies of ``POST /v1/jobs``, ``/v1/databases`` and ``/corrections``."""
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    for name, annotation in BODY_SCHEMAS.items():
        body_schema = TypeAdapter(annotation).json_schema(ref_template="#/components/schemas/{model}")
        components.update(body_schema.pop("$defs", {}))
        components[name] = body_schema


def create_app(settings: Settings | None = None) -> FastAPI:
    """The FastAPI app (``settings`` default: :func:`~service.settings.get_settings`, i.e. ``SEGUE_*``)."""
    settings = settings or get_settings()
    app = FastAPI(
        title="Segue",
        version=API_VERSION,
        description=DESCRIPTION,
        lifespan=lifespan,
        openapi_tags=[
            {"name": "clips", "description": "uploaded motions"},
            {"name": "databases", "description": "clips + a build spec, built by a job"},
            {"name": "files", "description": "other input files of requests (e.g. MIDI music)"},
            {"name": "characters", "description": "characters for a viewer: bindings and models"},
            {"name": "jobs", "description": "synthesis requests, results and reports"},
            {"name": "events", "description": "job events (WebSocket stream, HTTP fallback)"},
            {"name": "health", "description": "liveness, readiness and metrics"},
        ],
    )
    app.state.settings = settings
    app.state.metrics = Metrics()
    app.state.backend = None
    app.state.session_quota = SessionQuota(settings.max_sessions)
    # live sessions' engines (the only ones loaded here)
    app.state.engines = EngineCache(settings.engine_cache_mb << 20)
    install_error_handlers(app)
    for module in (
        clips,
        files,
        characters,
        databases,
        annotation_routes,
        movement_graphs,
        jobs,
        events,
        health,
        sessions,
        control_sessions,
    ):
        app.include_router(module.router)
    # innermost first: CatchAll turns a bug into the contract's 500 (keeping the connection), metrics
    # count it, the guard refuses foreign hosts and origins before anything else runs, and CORS (only
    # when origins are configured) answers preflights for the origins it allows
    app.add_middleware(CatchAll)
    app.add_middleware(HttpMetricsMiddleware, metrics=app.state.metrics)
    app.add_middleware(
        HostOriginGuard, allowed_hosts=settings.allowed_hosts, cors_origins=settings.cors_origins
    )
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(settings.cors_origins),
            allow_methods=["GET", "POST", "DELETE"],
            allow_headers=["Authorization", "Content-Type"],
            max_age=600,
        )
    mount_web(app)  # the browser front end: web/ at / for every path no API route matches

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = get_openapi(
                title=app.title,
                version=app.version,
                description=app.description,
                routes=app.routes,
                tags=app.openapi_tags,
            )
            _add_body_schemas(schema)
            add_links(schema)
            app.openapi_schema = schema
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    return app


def run(
    host: str = "127.0.0.1", port: int = 8000, settings: Settings | None = None, log_level: str = "info"
) -> None:
    """Serve the API with uvicorn in this process (the embedded backend spawns its own workers),
    with the request timeout and connection limit of :mod:`service.server`."""
    from .server import serve

    settings = settings or get_settings()
    serve(create_app(settings), settings, host, port, log_level)
