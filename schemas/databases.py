"""Database build specs (a discriminated union on ``kind``) and database status."""

from __future__ import annotations

import hashlib
import json
from datetime import datetime
from enum import StrEnum
from typing import Any, Literal

from pydantic import Field, field_validator

from .bases import DatabaseSpecBase
from .clips import LabelRange
from .common import SCHEMA_VERSION, Strict


class ClipsDatabaseSpec(DatabaseSpecBase):
    """A plain motion library: the clips parsed, resampled to one rate and converted to metres.

    Serves the ``clip`` engine (excerpts) and is the common part of every other kind."""

    kind: Literal["clips"] = "clips"


MIN_SPEED, MAX_SPEED = 0.5, 2.0
"""The playback speeds a graph spec's ``speeds`` may ask for (time-scaled copies of its clips)."""


class GraphDatabaseSpec(DatabaseSpecBase):
    """Motion-graph database (Arikan & Forsyth 2002).

    Transition costs compare joint positions and velocities in the torso frame and the torso's
    velocity and acceleration, each normalised by the database's largest frame-to-frame change, so
    ``tau`` is in units of "one frame of typical motion"."""

    kind: Literal["graph"] = "graph"
    fps: float | None = Field(
        default=30.0, ge=1, le=1000, description="database rate (graphs work at 30 fps)"
    )
    tau: float = Field(default=1.0, gt=0, le=100, description="edge threshold on the transition cost")
    joint_weights: dict[str, float] = Field(
        default_factory=dict, description="per joint name; default: feet 4, legs 2, hands 0.5, others 1"
    )
    velocity_weight: float = Field(default=1.0, ge=0, le=100)
    min_jump_frames: int = Field(
        default=10, ge=1, le=10000, description="ignore cuts within a clip closer than this to playing on"
    )
    mirror: bool = Field(
        default=False,
        description="add the mirror image of every clip (left and right exchanged), named '<clip> (mirror)'",
    )
    candidates: Literal["auto", "indexed", "all_pairs"] = Field(
        default="auto",
        description=(
            "how the build finds transitions: 'all_pairs' compares every pair of frames (exact, time "
            "N^2), 'indexed' descends from a nearest-neighbour index's seeds (near-linear, keeps the "
            "best cuts of each frame), 'auto' = all_pairs up to 20,000 frames, else indexed"
        ),
    )
    speeds: list[float] = Field(
        default_factory=list,
        max_length=8,
        description=(
            "add a copy of every clip (and mirror image) played at each of these speeds, resampled to "
            "the database rate, named '<clip> (x0.9)': more walking speeds and turn rates to cut "
            f"between; each in [{MIN_SPEED:g}, {MAX_SPEED:g}], not 1, no repeats"
        ),
    )

    @field_validator("speeds")
    @classmethod
    def _sane_speeds(cls, speeds: list[float]) -> list[float]:
        for s in speeds:
            if not (MIN_SPEED <= s <= MAX_SPEED) or s == 1.0:
                raise ValueError(
                    f"speeds: {s:g} is not a playback speed a copy can have: each must be in "
                    f"[{MIN_SPEED:g}, {MAX_SPEED:g}] and not 1 (the clips themselves), e.g. [0.9, 1.1]"
                )
        repeated = sorted({s for s in speeds if speeds.count(s) > 1})
        if repeated:
            raise ValueError(f"speeds: {', '.join(f'{s:g}' for s in repeated)} given more than once")
        return speeds


# The spec union and its validation are built from the engine registry
# (engines.registry.spec_union / parse_database_spec), which names every kind's model.
from .movement_graph import DerivedFrom  # noqa: E402

MIRROR_VERSION = 2
"""How mirror images are made (:func:`motion.mirror.mirror`); part of the id of every database whose
spec asks for them, so a spec built with an older convention is built anew when posted again
(2: the skeleton's joint frames kept, one convention over the library's clips; 1 had every joint
frame of a rig whose bones lie along a local axis turned half way round)."""


def database_id(spec: DatabaseSpecBase, clip_hashes: list[str]) -> str:
    """Content address of a database: sha256 of the clips' content hashes (in spec order), the
    canonical spec JSON (sorted keys, clip file references replaced by hashes, every clip named as
    reports name it; a graph spec's empty ``speeds`` left out), the schema version and, for specs
    with ``mirror`` on, :data:`MIRROR_VERSION`. ``segue build`` and ``POST /v1/databases`` give the
    same id to the same clips and spec."""
    canonical = spec.model_dump(mode="json", exclude={"name"})
    for entry, source, digest in zip(canonical["clips"], spec.clips, clip_hashes, strict=True):
        entry.pop("bvh", None)
        entry["clip"] = digest
        entry["name"] = source.display_name()
    if canonical.get("speeds") == []:
        del canonical["speeds"]  # no copies: the id a spec had before graph specs had ``speeds``
    identity: dict[str, Any] = {"schema": SCHEMA_VERSION, "spec": canonical}
    if canonical.get("mirror") is True:
        identity["mirror_images"] = MIRROR_VERSION
    payload = json.dumps(identity, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(payload.encode()).hexdigest()


class DatabaseStatus(StrEnum):
    queued = "queued"
    building = "building"
    ready = "ready"
    failed = "failed"


class SkeletonSummary(Strict):
    """The joint hierarchy every clip of a database shares (offsets may differ per performer)."""

    joints: list[str]
    parents: list[int] = Field(description="parent index of each joint (-1 for the root)")
    hips: str = Field(
        description="the joint that carries the body (floor position and root motion): the hips, "
        "which is not joint 0 on rigs whose root is a static ground node (Bandai-Namco's joint_Root)"
    )
    static_root: bool = Field(description="joint 0 stays put on the floor in every clip")
    hip_height_m: float | None = Field(
        default=None,
        description="the hips' height above the ankles (their mean) in the skeleton's zero pose, "
        "metres; null when its hips and feet are not recognised. A result put on a character "
        "(?character=) travels the root path scaled by about the character's own hip height over "
        "this (docs/retargeting.md), so a client placing goals for its character divides their "
        "distances by that ratio",
    )


class ClipSummary(Strict):
    """One clip of a database as the engines see it."""

    name: str = Field(description="the clip's name in requests and reports")
    frames: int = Field(description="frames at the database rate")
    source_units: str | None = Field(
        default=None, description="length unit of the file (declared or guessed; the database is metres)"
    )
    labels: list[LabelRange] = Field(default_factory=list, description="label ranges (database frames)")
    role: Literal["control", "target", "leader", "follower"] | None = Field(
        default=None, description="its part in a control pair or a couple"
    )


class DroppedClip(Strict):
    """A clip a graph build left out of the motion graph, and why."""

    clip: str
    frames: int = Field(description="its frames at the database rate")
    reason: str


class GraphKept(Strict):
    """What a graph build kept: the part of the graph a search can play (the strongly connected
    component of clips chosen by the build: the one with the most locomotion, then frames) and the
    clips outside it (their frames are never played)."""

    candidates: str = Field(description="how transitions were found: 'all_pairs' or 'indexed'")
    leaf_edges: int = Field(description="transitions of the kept graph")
    kept_clips: int
    kept_frames: int
    moving_frames: int = Field(description="kept frames whose body travels faster than 0.5 m/s")
    dropped_frames: int
    dropped: list[DroppedClip] = Field(description="every clip outside the kept component, and why")


class DatabaseSummary(Strict):
    """What a ready database holds, for clients that did not build it: its kind, clips, label
    vocabulary, skeleton and units."""

    kind: str
    fps: float
    units: Literal["m"] = Field(default="m", description="every length of the database and its results")
    clips: list[ClipSummary]
    labels: list[str] = Field(description="the label vocabulary (annotated databases), sorted")
    skeleton: SkeletonSummary
    control: Literal["motion", "path"] | None = Field(
        default=None,
        description="control databases: driven by a control motion (a dance leader: pairs with a "
        "control clip) or by a floor path (walks: controls derived from the targets)",
    )
    couples: bool = Field(
        default=False, description="rhythm databases with partners (requests may ask couples)"
    )
    graph: GraphKept | None = Field(
        default=None, description="graph databases: the clips and frames the build kept, and those left out"
    )


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
    summary: DatabaseSummary | None = Field(
        default=None, description="ready databases: clips, labels, skeleton and units (GET only)"
    )
    derived_from: DerivedFrom | None = Field(
        default=None, description="a database derived by graph edits: its parent and the edits"
    )
