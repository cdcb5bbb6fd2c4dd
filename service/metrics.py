"""Prometheus metrics, hand-written (text exposition format 0.0.4, no client library).

Counters live in the API process: HTTP requests by route template, jobs submitted by kind, jobs
finished by status (terminal events this process recorded), WebSocket connections (gauge), events
sent over WebSockets and solution events coalesced away for slow clients. ``/metrics`` adds the
backend's numeric health facts as ``segue_backend_<name>`` gauges.
"""

from __future__ import annotations

import math
import re
from collections import defaultdict
from collections.abc import Awaitable, Callable, Mapping
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from schemas import JobEvent
from workers.backend import EventHub

Labels = tuple[tuple[str, str], ...]

_HELP: dict[str, tuple[str, str]] = {
    "segue_http_requests_total": ("counter", "HTTP requests by route template, method and status."),
    "segue_jobs_submitted_total": ("counter", "Jobs submitted through this API process, by kind."),
    "segue_jobs_finished_total": ("counter", "Terminal job events recorded by this API process, by status."),
    "segue_ws_connections": ("gauge", "Open WebSocket event streams."),
    "segue_events_sent_total": ("counter", "Job events sent over WebSockets."),
    "segue_events_coalesced_total": ("counter", "Solution events dropped for slow WebSocket clients."),
}


def _escape(value: str) -> str:
    return value.replace("\\", "\\\\").replace("\n", "\\n").replace('"', '\\"')


def _number(value: float) -> str:
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "+Inf" if value > 0 else "-Inf"
    return repr(float(value)) if not float(value).is_integer() else str(int(value))


class Metrics:
    """Counters and gauges keyed by name and labels (single event loop: no locking needed)."""

    def __init__(self) -> None:
        self._values: dict[str, dict[Labels, float]] = defaultdict(dict)
        for name in _HELP:
            self._values[name]

    def inc(self, name: str, amount: float = 1.0, **labels: str) -> None:
        """Add to a counter (or a gauge)."""
        key = tuple(sorted(labels.items()))
        family = self._values[name]
        family[key] = family.get(key, 0.0) + amount

    def value(self, name: str, **labels: str) -> float:
        """The current value of one series (0 when never set)."""
        return self._values[name].get(tuple(sorted(labels.items())), 0.0)

    def render(self, gauges: Mapping[str, float] | None = None) -> str:
        """The exposition text; ``gauges`` adds extra unlabelled gauges (e.g. backend facts)."""
        lines: list[str] = []
        for name, series in self._values.items():
            kind, text = _HELP.get(name, ("untyped", name))
            lines += [f"# HELP {name} {text}", f"# TYPE {name} {kind}"]
            if not series and kind == "gauge":
                lines.append(f"{name} 0")
            for labels, value in sorted(series.items()):
                label_text = ",".join(f'{k}="{_escape(v)}"' for k, v in labels)
                lines.append(
                    f"{name}{{{label_text}}} {_number(value)}" if labels else f"{name} {_number(value)}"
                )
        for name, value in sorted((gauges or {}).items()):
            lines += [
                f"# HELP {name} Backend health fact.",
                f"# TYPE {name} gauge",
                f"{name} {_number(value)}",
            ]
        return "\n".join(lines) + "\n"


def backend_gauges(health: Mapping[str, Any], prefix: str = "segue_backend_") -> dict[str, float]:
    """The numeric facts of a backend's ``health()`` as gauge names and values (nested dicts flattened)."""
    out: dict[str, float] = {}
    for key, value in health.items():
        name = prefix + re.sub(r"[^a-zA-Z0-9_]", "_", str(key))
        if isinstance(value, bool | int | float):
            out[name] = float(value)
        elif isinstance(value, Mapping):
            out.update(backend_gauges(value, name + "_"))
    return out


class HttpMetricsMiddleware:
    """Counts every HTTP request by route template (``/v1/jobs/{job_id}``), method and status."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        status = [500]

        async def send_wrapper(message: Message) -> None:
            if message["type"] == "http.response.start":
                status[0] = int(message["status"])
            await send(message)

        try:
            await self.app(scope, receive, send_wrapper)
        finally:
            route = scope.get("route")
            template = getattr(route, "path", None) or "unmatched"
            self.metrics.inc(
                "segue_http_requests_total", route=template, method=scope["method"], status=str(status[0])
            )


def observe_terminal_events(hub: EventHub, metrics: Metrics, since: float) -> None:
    """Count terminal events as the backend records them (``segue_jobs_finished_total{status}``).

    Events older than ``since`` (unix time; replays of jobs that finished before this process
    started) are not counted. The backend protocol has no event hook, so this wraps the hub's
    ``append`` on the instance; behaviour is unchanged (the wrapper returns what ``append`` returns).
    """
    append: Callable[[JobEvent], Awaitable[bool]] = hub.append

    async def counting_append(event: JobEvent) -> bool:
        added = await append(event)
        if added and event.type.terminal and event.time >= since:
            metrics.inc("segue_jobs_finished_total", status=event.type.value)
        return added

    hub.append = counting_append  # type: ignore[method-assign]
