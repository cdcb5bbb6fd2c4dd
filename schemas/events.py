"""Job events: what a job reports while it runs, in order, with increasing ids (resume with ``after``)."""

from __future__ import annotations

from enum import StrEnum
from typing import Any

from pydantic import BaseModel, Field


class EventType(StrEnum):
    queued = "queued"
    started = "started"
    progress = "progress"
    solution = "solution"
    alternative = "alternative"
    done = "done"
    failed = "failed"
    cancelled = "cancelled"

    @property
    def terminal(self) -> bool:
        return self in (EventType.done, EventType.failed, EventType.cancelled)


class JobEvent(BaseModel):
    """One event of a job.

    ``data`` by type: ``progress`` ``{"fraction": 0..1, "message"}``; ``solution`` ``{"score",
    "terms", "elapsed_ms", "result", "ok", "reasons"}`` (a new best: scores strictly decrease; lower
    is better; ``ok``/``reasons`` from the result's quality report); ``alternative`` the same for
    a result that is not a new best (e.g. the graph engine's other local minima);
    ``done``/``cancelled`` ``{"result", "ok", "reasons", "stopped", "stopped_reason"}`` (the best
    result, or null; ``stopped``: ``"work"`` when the search did the work the request asked for,
    ``"budget"`` when the ``budget_s`` cap cut it short (the answer may differ from an unhurried
    run's), ``"cancelled"``, or ``"time_limit"`` when the supervisor stopped a job that overran);
    ``failed`` ``{"error": {"code", "message"}}``.

    ``attempt`` is the run of the job that published the event (its fencing token): 0 before any
    run started (``queued``, a cancel while queued), then the attempt each ``started`` event opens,
    1, 2...; a run that lost the job to a later attempt (a worker that hung past the reclaim time)
    publishes nothing more, so every event after a ``started`` carries that start's attempt.
    """

    id: int = Field(ge=1)
    job: str
    type: EventType
    time: float = Field(description="unix time, seconds")
    data: dict[str, Any] = Field(default_factory=dict)
    attempt: int = Field(default=0, ge=0, description="the run that published it (0: before any run)")
