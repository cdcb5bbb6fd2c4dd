"""Database build specs (a discriminated union on ``kind``) and database status."""

from __future__ import annotations

import hashlib
import json
from datetime import datetime
from enum import StrEnum
from typing import Annotated, Any, Literal

from pydantic import Field, TypeAdapter

from .bases import DatabaseSpecBase
from .common import SCHEMA_VERSION, Strict


class ClipsDatabaseSpec(DatabaseSpecBase):
    """A plain motion library: the clips parsed, resampled to one rate and converted to metres.

    Serves the ``clip`` engine (excerpts) and is the common part of every other kind."""

    kind: Literal["clips"] = "clips"


class GraphDatabaseSpec(DatabaseSpecBase):
    """Motion-graph database (Arikan & Forsyth 2002).

    Transition costs compare joint positions and velocities in the torso frame and the torso's
    velocity and acceleration, each normalised by the database's largest frame-to-frame change, so
    ``tau`` is in units of "one frame of typical motion"."""

    kind: Literal["graph"] = "graph"
    fps: float | None = Field(
        default=30.0, gt=0, le=1000, description="database rate (graphs work at 30 fps)"
    )
    tau: float = Field(default=1.0, gt=0, le=100, description="edge threshold on the transition cost")
    joint_weights: dict[str, float] = Field(
        default_factory=dict, description="per joint name; default: feet 4, legs 2, hands 0.5, others 1"
    )
    velocity_weight: float = Field(default=1.0, ge=0, le=100)
    min_jump_frames: int = Field(
        default=10, ge=1, le=10000, description="ignore cuts within a clip closer than this to playing on"
    )


# Kind-specific specs defined in their engine's schema module (they import DatabaseSpecBase from here).
from .annotations import AnnotatedDatabaseSpec  # noqa: E402
from .control import ControlDatabaseSpec  # noqa: E402
from .rhythm import RhythmDatabaseSpec  # noqa: E402

DatabaseSpec = Annotated[
    ClipsDatabaseSpec | ControlDatabaseSpec | GraphDatabaseSpec | AnnotatedDatabaseSpec | RhythmDatabaseSpec,
    Field(discriminator="kind"),
]
_SPEC_ADAPTER: TypeAdapter[Any] = TypeAdapter(DatabaseSpec)


def parse_database_spec(data: Any) -> DatabaseSpecBase:
    """Validate a database spec (dict or JSON text); raises pydantic's ValidationError."""
    if isinstance(data, str | bytes):
        return _SPEC_ADAPTER.validate_json(data)  # type: ignore[no-any-return]
    return _SPEC_ADAPTER.validate_python(data)  # type: ignore[no-any-return]


def database_id(spec: DatabaseSpecBase, clip_hashes: list[str]) -> str:
    """Content address of a database: sha256 of the clips' content hashes (in spec order), the
    canonical spec JSON (sorted keys, clip file references replaced by hashes) and the schema version."""
    canonical = spec.model_dump(mode="json", exclude={"name"})
    for entry, digest in zip(canonical["clips"], clip_hashes, strict=True):
        entry.pop("bvh", None)
        entry["clip"] = digest
    payload = json.dumps({"schema": SCHEMA_VERSION, "spec": canonical}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(payload.encode()).hexdigest()


class DatabaseStatus(StrEnum):
    queued = "queued"
    building = "building"
    ready = "ready"
    failed = "failed"


class DatabaseInfo(Strict):
    id: str
    kind: str
    name: str | None = None
    status: DatabaseStatus
    clips: list[str] = Field(description="clip names as used in reports")
    frames: int = 0
    fps: float | None = None
    build_job: str | None = Field(default=None, description="the job building it (events show progress)")
    error: str | None = None
    created_at: datetime
