"""``/healthz`` (liveness and backend facts), ``/readyz`` (readiness: the store, Redis when used,
live workers) and ``/metrics`` (Prometheus text exposition).

``/healthz`` stays cheap (no store call): a load balancer's liveness probe must not restart an API
process because its store stalls. ``/readyz`` answers 503 naming each part that is not ready, so
traffic goes elsewhere (or waits) while the store or the workers are away.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, PlainTextResponse

from schemas import SCHEMA_VERSION
from workers.storage_errors import storage_problem

from ..deps import MetricsDep
from ..metrics import backend_gauges

log = logging.getLogger("segue.service")

router = APIRouter(tags=["health"])


async def _backend_health(request: Request) -> dict[str, Any] | None:
    backend = getattr(request.app.state, "backend", None)
    if backend is None:
        return None
    try:
        return dict(await backend.health())
    except Exception as exc:  # health must answer even when the backend is broken
        log.warning("backend health check failed: %r", exc)
        return {"error": f"{type(exc).__name__}: {exc}"}


@router.get("/healthz", responses={503: {"description": "the backend is down or not started"}})
async def healthz(request: Request) -> JSONResponse:
    """``{"ok": true, "backend": {...}}`` while the job backend answers; 503 otherwise."""
    health = await _backend_health(request)
    ok = health is not None and "error" not in health
    body = {"ok": ok, "schema_version": SCHEMA_VERSION, "backend": health}
    return JSONResponse(body, status_code=200 if ok else 503)


READY_PROBE_KEY = "probe/readyz"
"""The key ``/readyz`` asks the store about (whether it exists does not matter: that it answers)."""


async def _store_ready(request: Request) -> str | None:
    """None when the store answers a small call within ``SEGUE_STORE_TIMEOUT_S``, else why not."""
    store = getattr(request.app.state, "store", None)
    if store is None:
        return "the store is not open (the service is starting or stopping)"
    try:
        await asyncio.to_thread(store.objects.exists, READY_PROBE_KEY)
    except Exception as exc:
        problem = storage_problem(exc)
        return problem[1] if problem is not None else f"{type(exc).__name__}: {exc}"
    return None


def _backend_ready(health: dict[str, Any] | None) -> dict[str, str]:
    """The backend's parts that are not ready (``backend``/``redis``, ``workers``) and why."""
    if health is None:
        return {"backend": "the job backend is not running (the service is starting or stopping)"}
    if "error" in health:
        part = "redis" if health.get("backend") == "redis" else "backend"
        return {part: str(health["error"])}
    alive = health.get("workers_ready", health.get("workers", 0))
    if not alive:
        return {"workers": "no worker is alive to run jobs (start `segue worker`, or wait for them)"}
    return {}


@router.get(
    "/readyz",
    responses={503: {"description": "a part is not ready: `not_ready` names each and why"}},
)
async def readyz(request: Request) -> JSONResponse:
    """``{"ready": true, "checks": {...}}`` when the store answers, the job backend (and Redis, when
    used) answers and at least one worker is alive; 503 with ``not_ready`` naming each part that
    is not (``store``, ``backend`` or ``redis``, ``workers``)."""
    store_problem, health = await asyncio.gather(_store_ready(request), _backend_health(request))
    not_ready = _backend_ready(health)
    if store_problem is not None:
        not_ready = {"store": store_problem, **not_ready}
    checks = {part: "ok" for part in ("store", "backend", "workers") if part not in not_ready}
    body: dict[str, Any] = {"ready": not not_ready, "checks": checks}
    if not_ready:
        body["not_ready"] = not_ready
    return JSONResponse(body, status_code=503 if not_ready else 200, headers={"Cache-Control": "no-store"})


@router.get("/metrics", response_class=PlainTextResponse)
async def metrics(request: Request, registry: MetricsDep) -> PlainTextResponse:
    """Prometheus metrics (text format 0.0.4)."""
    health = await _backend_health(request) or {}
    gauges = backend_gauges(health)
    gauges["segue_backend_up"] = 0.0 if not health or "error" in health else 1.0
    return PlainTextResponse(registry.render(gauges), media_type="text/plain; version=0.0.4; charset=utf-8")
