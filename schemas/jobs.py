"""The clip engine's request, job status and info (every engine's request model, and the union of
them, are named by :mod:`engines.registry`)."""

from __future__ import annotations

from datetime import datetime
from enum import StrEnum
from typing import Literal

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

    def named_clip_frames(self) -> list[tuple[str, str, int]]:
        """The excerpt's first frame, and its last when ``end`` is given."""
        out = [("start", self.clip, self.start)]
        if self.end is not None:
            out.append(("end", self.clip, self.end - 1))
        return out

    @model_validator(mode="after")
    def _range(self) -> ClipRequest:
        if self.end is not None and self.end <= self.start:
            raise ValueError(f"end ({self.end}) must be after start ({self.start})")
        return self


class RequestError(ValueError):
    """A job request that is not an object or names no known engine
    (:func:`engines.registry.parse_job_request`, which validates requests with their engine's model)."""


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
