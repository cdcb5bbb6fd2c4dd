"""Reports: what a result is made of and how good it is."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field


class ProvenanceEntry(BaseModel):
    clip: str = Field(description="the clip as named in the database spec")
    frame: int = Field(description="source frame index in that clip (at the database rate)")
    weights: list[float] | None = Field(default=None, description="blend weights where frames were blended")


class Report(BaseModel):
    """The report of one result, measured on the motion returned (``motion.quality.assess``):
    whether it is ``ok`` and why not, each constraint's error with ``satisfied``, physical
    plausibility against the database's examples, score terms, metrics and per-frame provenance."""

    job: str
    result: str
    engine: str
    ok: bool | None = Field(
        default=None,
        description="every constraint satisfied and every plausibility figure within its limit "
        "(null for reports written before quality reports existed)",
    )
    reasons: list[str] = Field(default_factory=list, description="why ok is false, one line each")
    score: float
    terms: dict[str, float] = Field(default_factory=dict)
    constraint_errors: dict[str, Any] = Field(
        default_factory=dict,
        description="per constraint (body[0], joint[1], length, ...): its error measured on the "
        "output, the tolerance and satisfied",
    )
    plausibility: dict[str, dict[str, Any]] = Field(
        default_factory=dict,
        description="per figure (root_speed, turn_rate, foot_slide, floor_penetration, joint_step, "
        "join_spikes, jerk): value, unit, reference (the examples), limit and ok",
    )
    metrics: dict[str, float] = Field(default_factory=dict)
    frames: int
    fps: float
    provenance: list[ProvenanceEntry]
    annotations: dict[str, Any] = Field(default_factory=dict)
    stopped: Literal["work", "budget", "cancelled"] | None = Field(
        default=None,
        description="why the search ended, on the job's final result (null on intermediate results): "
        "'work' (it did the work the request asked for: the same request and seed give the same "
        "answer anywhere), 'budget' (the budget_s cap cut it short: the answer may differ from an "
        "unhurried run's) or 'cancelled'",
    )
    stopped_reason: str | None = Field(default=None, description="what 'stopped' means for the answer")
