"""Job requests (a discriminated union on ``engine``) and job status."""

from __future__ import annotations

import json
from datetime import datetime
from enum import StrEnum
from typing import Annotated, Any, Literal

from pydantic import Field, model_validator

from .bases import JobRequestBase
from .common import Strict


class ClipRequest(JobRequestBase):
    """Excerpt of a database clip: frames ``[start, end)``, optionally resampled, mirrored and placed.

    The simplest engine: one solution, exact provenance. Used to preview clips and as the smallest
    end-to-end job of the runtime."""

    engine: Literal["clip"] = "clip"
    clip: str = Field(description="clip name as in the database spec")
    start: int = Field(default=0, ge=0)
    end: int | None = Field(default=None, gt=0, description="exclusive; default: the clip's end")
    mirror: bool = False
    position: tuple[float, float] | None = Field(
        default=None, description="[x, z] metres for the first frame"
    )
    heading_deg: float | None = Field(default=None, description="facing at the first frame (0 = +Z, 90 = +X)")

    @model_validator(mode="after")
    def _range(self) -> ClipRequest:
        if self.end is not None and self.end <= self.start:
            raise ValueError(f"end ({self.end}) must be after start ({self.start})")
        return self


JobRequest = Annotated[ClipRequest, Field(discriminator="engine")]
"""The request union of the built-in engines (documented in the OpenAPI schema)."""

REQUEST_MODELS: dict[str, type[JobRequestBase]] = {"clip": ClipRequest}
"""Request model by engine name; engine plugins add theirs with :func:`register_request_model`."""


class RequestError(ValueError):
    """A job request that is not an object or names no known engine."""


def register_request_model(engine: str, model: type[JobRequestBase]) -> None:
    REQUEST_MODELS[engine] = model


def parse_job_request(data: Any) -> JobRequestBase:
    """Validate a job request (dict or JSON text) with its engine's model.

    Raises :class:`RequestError` for a non-object or an unknown engine and pydantic's
    ``ValidationError`` for invalid fields.
    """
    if isinstance(data, str | bytes):
        try:
            data = json.loads(data)
        except ValueError as exc:
            raise RequestError(f"the request is not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise RequestError("a job request must be a JSON object")
    engine = data.get("engine")
    model = REQUEST_MODELS.get(engine) if isinstance(engine, str) else None
    if model is None:
        raise RequestError(f"unknown engine {engine!r}; available: {', '.join(sorted(REQUEST_MODELS))}")
    return model.model_validate(data)


class JobKind(StrEnum):
    synth = "synth"
    build = "build"
    task = "task"
    """A small job the API runs for a request (parsing an upload, making an export): not listed."""


class JobStatus(StrEnum):
    queued = "queued"
    running = "running"
    done = "done"
    failed = "failed"
    cancelled = "cancelled"

    @property
    def finished(self) -> bool:
        return self in (JobStatus.done, JobStatus.failed, JobStatus.cancelled)


class JobInfo(Strict):
    id: str
    kind: JobKind
    engine: str | None = None
    database: str | None = None
    status: JobStatus
    created_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None
    result: str | None = Field(default=None, description="id of the best result so far")
    error: str | None = None
    last_event: int = Field(default=0, description="id of the newest event")
    attempt: int = Field(default=0, ge=0, description="the run holding the job (its latest `started`)")
    owner: str | None = Field(default=None, description="the principal that submitted the job")


# Engine request models defined in their own modules (they import JobRequestBase from schemas.bases).
from .annotations import AnnotationRequest  # noqa: E402
from .control import ControlRequest  # noqa: E402
from .graph import GraphRequest  # noqa: E402
from .rhythm import RhythmRequest  # noqa: E402

JobRequest = Annotated[  # type: ignore[misc,assignment]
    ClipRequest | GraphRequest | ControlRequest | AnnotationRequest | RhythmRequest,
    Field(discriminator="engine"),
]
REQUEST_MODELS.update(
    graph=GraphRequest, control=ControlRequest, annotations=AnnotationRequest, rhythm=RhythmRequest
)
