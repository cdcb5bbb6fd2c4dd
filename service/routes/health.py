"""``/healthz`` (liveness and backend facts) and ``/metrics`` (Prometheus text exposition)."""

from __future__ import annotations

import logging
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, PlainTextResponse

from schemas import SCHEMA_VERSION

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


@router.get("/metrics", response_class=PlainTextResponse)
async def metrics(request: Request, registry: MetricsDep) -> PlainTextResponse:
    """Prometheus metrics (text format 0.0.4)."""
    health = await _backend_health(request) or {}
    gauges = backend_gauges(health)
    gauges["segue_backend_up"] = 0.0 if not health or "error" in health else 1.0
    return PlainTextResponse(registry.render(gauges), media_type="text/plain; version=0.0.4; charset=utf-8")
