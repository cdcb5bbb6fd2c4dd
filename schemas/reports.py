"""Reports: what a result is made of and how good it is."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field


class ProvenanceEntry(BaseModel):
    clip: str = Field(description="the clip as named in the database spec")
    frame: int = Field(description="source frame index in that clip (at the database rate)")
    weights: list[float] | None = Field(default=None, description="blend weights where frames were blended")


class Report(BaseModel):
    """The report of one result: score terms, constraint errors, metrics and per-frame provenance."""

    job: str
    result: str
    engine: str
    score: float
    terms: dict[str, float] = Field(default_factory=dict)
    constraint_errors: dict[str, Any] = Field(default_factory=dict)
    metrics: dict[str, float] = Field(default_factory=dict)
    frames: int
    fps: float
    provenance: list[ProvenanceEntry]
    annotations: dict[str, Any] = Field(default_factory=dict)
