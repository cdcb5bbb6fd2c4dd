"""What the add-on knows in one Blender session: the server, its clips and databases, the rigs
uploaded, the job being followed and its quality report (plain Python; the panels draw it)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from .client import SegueClient
from .jobs import JobRunner
from .local_service import LocalService


@dataclass(slots=True)
class GoalResult:
    """A body goal of the last result: where it is (Blender world), where the character's hips
    were at its frame, the floor distance between them (cm) and whether that is within the
    report's tolerance (at the character's scale); ``report_cm`` is the report's own error,
    measured on the database performers' motion before it was put on the character."""

    name: str
    position: tuple[float, float, float]
    reached: tuple[float, float, float] | None
    error_cm: float | None
    satisfied: bool
    report_cm: float | None = None


@dataclass(slots=True)
class JobView:
    """The job being followed, as the panel shows it."""

    database: str
    armatures: list[str]
    action_name: str = ""
    id: str = ""
    state: str = "submitting"
    pressed_at: float = field(default_factory=time.perf_counter)
    first_solution_s: float | None = None
    solutions: int = 0
    shown: str = ""
    score: float | None = None
    ok: bool | None = None
    reasons: list[str] = field(default_factory=list)
    goals: list[GoalResult] = field(default_factory=list)
    message: str = ""
    runner: JobRunner | None = None
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def running(self) -> bool:
        return self.state in ("submitting", "queued", "running", "cancelling")


@dataclass(slots=True)
class Session:
    client: SegueClient | None = None
    status: str = "not connected"
    error: str = ""
    health: dict[str, Any] = field(default_factory=dict)
    clips: list[dict[str, Any]] = field(default_factory=list)
    databases: list[dict[str, Any]] = field(default_factory=list)
    rig_files: dict[tuple[str, str], str] = field(default_factory=dict)
    uploaded: list[str] = field(default_factory=list)
    clip_labels: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    """Label ranges of the clips uploaded this session (their actions' pose markers)."""
    job: JobView | None = None
    local: LocalService | None = None

    @property
    def url(self) -> str:
        return self.client.url if self.client is not None else ""

    def database(self, ref: str) -> dict[str, Any] | None:
        """A database of the list by id, id prefix or name."""
        for db in self.databases:
            if ref in (db.get("id"), db.get("name")) or (
                len(ref) >= 6 and str(db.get("id", "")).startswith(ref)
            ):
                return db
        return None


SESSION = Session()
"""The add-on's one session."""
