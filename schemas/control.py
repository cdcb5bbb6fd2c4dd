"""Control-by-example engine (Hsu, Gentry & Popović 2004): database spec and request.

A control database holds synchronized example *pairs*: a control motion (a dance leader) and the
target motion it drives (the follower). A pair without a control (``"control": null``) derives it
from the target as the paper did for walks: the hips projected on the floor with a normalised
separation.

``pairs`` entries name clips like ``clips`` entries do (a path relative to the spec file for the CLI,
an uploaded file name or ``{"clip": id}`` for the API). Validation moves them into ``clips`` (target
then control, in pair order, each once) with explicit names, and leaves the pair holding those names,
so the runtime loads a control database like any other and its content address does not depend on
file paths.

Times are seconds; lengths metres; floor positions ``[x, z]``.
"""

from __future__ import annotations

import itertools
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from .bases import DatabaseSpecBase, JobRequestBase
from .clips import ClipSource
from .common import FEET_DESCRIPTION, FeetMode, Strict, feet_mode_of


class ControlPair(Strict):
    """One synchronized example: clip names (after validation) of the control and the target.

    ``control`` is ``None`` for a target whose control is derived from its own hips (walks).
    ``markers_s`` are the segment boundaries for ``segmentation.method = "markers"`` (seconds from
    the pair's first frame, increasing)."""

    control: str | None = Field(default=None, description="clip name of the control motion (leader)")
    target: str = Field(description="clip name of the target motion (follower)")
    markers_s: list[float] = Field(default_factory=list, max_length=100_000)

    @field_validator("markers_s")
    @classmethod
    def _increasing(cls, v: list[float]) -> list[float]:
        if any(b <= a for a, b in itertools.pairwise(v)) or any(m < 0 for m in v):
            raise ValueError("markers_s must be non-negative and strictly increasing (seconds)")
        return v


class Segmentation(Strict):
    """How the example pairs are cut into instances (the paper's semantic segments).

    * ``beats``: motion beats of the control (Kim et al. 2003 via :mod:`motion.beats`), grouped by
      ``beats_per_segment`` (two-beat units for partner dance);
    * ``footplants``: a boundary at every footplant of the target (steps), grouped by
      ``steps_per_segment``;
    * ``fixed``: segments of ``seconds``;
    * ``markers``: the pairs' ``markers_s``.

    ``overlap`` adds instances starting at every unit (beat, step) instead of every
    ``*_per_segment`` units (default), giving the DP more phases to choose from: on the CMU salsa
    couples it lowers the leave-one-out follower error (choice beyond the paper, which cuts each
    example once)."""

    method: Literal["beats", "footplants", "fixed", "markers"] = "beats"
    beats_per_segment: int = Field(default=2, ge=1, le=16)
    steps_per_segment: int = Field(default=1, ge=1, le=8)
    seconds: float = Field(default=1.0, gt=0.05, le=30, description="segment length for 'fixed'")
    overlap: bool = Field(default=True, description="also start instances between segment boundaries")
    tempo_bpm: tuple[float, float] = Field(default=(90.0, 220.0), description="tempo prior of beat detection")
    beats_source: Literal["control", "target"] = Field(
        default="target", description="the motion whose beats cut the pair (both share the music)"
    )
    min_segment_s: float = Field(default=0.2, gt=0, le=30, description="shorter segments are dropped")
    max_segment_s: float = Field(default=4.0, gt=0, le=60, description="longer segments are dropped")

    @model_validator(mode="after")
    def _bounds(self) -> Segmentation:
        if self.max_segment_s <= self.min_segment_s:
            raise ValueError("max_segment_s must be larger than min_segment_s")
        lo, hi = self.tempo_bpm
        if not 0 < lo < hi <= 1000:
            raise ValueError("tempo_bpm must be (low, high) with 0 < low < high <= 1000")
        return self


def _ref_to_source(ref: Any, where: str) -> dict[str, Any]:
    if isinstance(ref, str):
        return {"bvh": ref}
    if isinstance(ref, dict):
        return dict(ref)
    if isinstance(ref, ClipSource):
        return ref.model_dump(exclude_none=True)
    raise ValueError(f"{where}: give a file name or a clip object like {{'bvh': 'a.bvh'}}")


def unequal_pair_problems(
    spec: ControlDatabaseSpec, frames: dict[str, int], fps: float
) -> tuple[list[str], list[str]]:
    """``(problems, warnings)`` of the pairs whose control and target lengths differ, ``frames``
    the clips' frames at the database rate ``fps``: problems under ``unequal_pairs = "refuse"``,
    warnings under ``"trim"``, one sentence per pair naming both lengths."""
    problems, warnings = [], []
    for i, p in enumerate(spec.pairs):
        if p.control is None or p.control not in frames or p.target not in frames:
            continue
        c, t = frames[p.control], frames[p.target]
        if c == t:
            continue
        line = f"pairs[{i}]: control {p.control!r} has {c} frames and target {p.target!r} {t} at {fps:g} fps"
        if spec.unequal_pairs == "trim":
            warnings.append(f"{line}: both cut to {min(c, t)} frames (unequal_pairs: trim)")
        else:
            problems.append(
                f"{line}: a synchronized pair has equal lengths (is it the right file?); set "
                '"unequal_pairs": "trim" to cut both to the shorter'
            )
    return problems, warnings


class ControlDatabaseSpec(DatabaseSpecBase):
    """Control-by-example database: synchronized (control, target) example pairs.

    Example: ``{"kind": "control", "pairs": [{"control": "60_01_scaled.bvh", "target":
    "61_01_scaled.bvh"}], "segmentation": {"method": "beats", "beats_per_segment": 2}}``."""

    kind: Literal["control"] = "control"
    pairs: list[ControlPair] = Field(min_length=1, max_length=1000)
    fps: float | None = Field(default=30.0, ge=1, le=1000, description="database rate (full-rate re-timing)")
    segmentation: Segmentation = Field(default_factory=Segmentation)
    control_joints: list[str] | None = Field(
        default=None, description="joints of the control point cloud (default: hips, head, hands)"
    )
    target_joints: list[str] | None = Field(
        default=None, description="joints of the target point cloud (default: hips, head, hands, feet)"
    )
    hip_separation_m: float = Field(
        default=0.2, gt=0, le=2, description="normalised hip separation of derived (walk) controls"
    )
    cluster_threshold_m: float = Field(
        default=0.0,
        ge=0,
        le=10,
        description="complete-linkage threshold on the RMS point distance of aligned control segments "
        "(metres; 0 keeps every instance)",
    )
    handhold_m: float = Field(default=0.2, gt=0, le=2, description="partners' hands closer than this hold")
    unequal_pairs: Literal["refuse", "trim"] = Field(
        default="refuse",
        description="a pair whose control and target differ in length (frames at the database rate): "
        "refused at submission, naming both lengths (default: synchronized captures have equal "
        "lengths, so a difference is most often the wrong file), or 'trim': both cut to the shorter, "
        "with a warning naming both lengths",
    )
    seed: int = Field(default=0, ge=0, le=2**32 - 1, description="choice of cluster representatives")

    @model_validator(mode="before")
    @classmethod
    def _pairs_to_clips(cls, data: Any) -> Any:
        """Fill ``clips`` from ``pairs`` (target then control, in order, each once) and leave clip
        names in the pairs; a pair reference equal to an existing clip's name or path reuses it."""
        if not isinstance(data, dict) or not isinstance(data.get("pairs"), list):
            return data
        data = dict(data)
        clips = [_ref_to_source(c, f"clips[{i}]") for i, c in enumerate(data.get("clips") or [])]
        by_key: dict[str, str] = {}
        for c in clips:
            name = c.get("name") or ClipSource.model_validate(c).display_name()
            c["name"] = name
            for key in (name, c.get("bvh"), c.get("clip")):
                if key:
                    by_key.setdefault(str(key), name)
        pairs = []
        for i, pair in enumerate(data["pairs"]):
            if not isinstance(pair, dict):
                raise ValueError(f"pairs[{i}]: give an object like {{'control': 'a.bvh', 'target': 'b.bvh'}}")
            pair = dict(pair)
            if pair.get("target") is None:
                raise ValueError(f"pairs[{i}]: 'target' is required")
            for role in ("target", "control"):
                ref = pair.get(role)
                if ref is None:
                    continue
                key = ref if isinstance(ref, str) else None
                if key is not None and key in by_key:
                    pair[role] = by_key[key]
                    continue
                source = _ref_to_source(ref, f"pairs[{i}].{role}")
                name = source.get("name") or ClipSource.model_validate(source).display_name()
                if name in by_key.values():
                    raise ValueError(
                        f"pairs[{i}].{role}: another clip is already named {name!r}; give this one a 'name'"
                    )
                source["name"] = name
                clips.append(source)
                for k in (name, source.get("bvh"), source.get("clip")):
                    if k:
                        by_key.setdefault(str(k), name)
                pair[role] = name
            pairs.append(pair)
        data["clips"] = clips
        data["pairs"] = pairs
        return data

    @model_validator(mode="after")
    def _pairs_named(self) -> ControlDatabaseSpec:
        names = {c.display_name() for c in self.clips}
        for i, p in enumerate(self.pairs):
            for role, ref in (("target", p.target), ("control", p.control)):
                if ref is not None and ref not in names:
                    raise ValueError(f"pairs[{i}].{role}: no clip named {ref!r}")
            if p.control == p.target:
                raise ValueError(f"pairs[{i}]: control and target are the same clip {p.target!r}")
        if self.segmentation.method == "markers":
            short = [i for i, p in enumerate(self.pairs) if len(p.markers_s) < 2]
            if short:
                raise ValueError(f"segmentation 'markers' needs at least 2 markers_s per pair; pairs {short}")
        return self


class TrajectorySmoothing(Strict):
    """Optional smoothing of a performed path before it drives the walk."""

    spatial_m: float = Field(default=0.0, ge=0, le=10, description="Gaussian sigma along the path, metres")
    temporal_s: float = Field(default=0.0, ge=0, le=10, description="Gaussian sigma in time, seconds")


class Trajectory(Strict):
    """A performed path: floor points ``[x, z]`` (metres) sampled at ``fps`` (e.g. a mouse at 30 Hz)."""

    fps: float = Field(gt=0, le=1000)
    points: list[tuple[float, float]] = Field(min_length=2, max_length=1_000_000)
    smoothing: TrajectorySmoothing = Field(default_factory=TrajectorySmoothing)
    max_speed_m_s: float = Field(
        default=4.0, gt=0, le=50, description="a path faster than this anywhere is refused"
    )
    speed_window_s: float = Field(default=0.5, gt=0, le=10, description="speed is measured over this window")


class ControlInput(Strict):
    """The control: a motion (``bvh``, the leader) or a trajectory (walks)."""

    bvh: str | None = Field(default=None, min_length=1, max_length=1024, examples=["60_12_scaled.bvh"])
    units: str | None = Field(default=None, description="declared length unit of the BVH (default: guessed)")
    trajectory: Trajectory | None = None

    @model_validator(mode="after")
    def _one(self) -> ControlInput:
        if (self.bvh is None) == (self.trajectory is None):
            raise ValueError("give exactly one of 'bvh' (a control motion) or 'trajectory' (a path)")
        if self.units is not None:
            from motion.units import METRES_PER_UNIT

            if self.units not in METRES_PER_UNIT:
                raise ValueError(f"unknown units {self.units!r}; use one of {', '.join(METRES_PER_UNIT)}")
        return self


class BodyPlacement(Strict):
    """Where the target's body (its hips on the floor) stands at a time: ``position`` ``[x, z]``
    metres in the control's world frame (a soft cost in the search, then met by a floor correction
    within the examples' limits; reported as ``body[i]``)."""

    time_s: float = Field(ge=0, le=86_400, description="seconds from the control's start")
    position: tuple[float, float] = Field(description="[x, z] metres, the control's world frame")

    @model_validator(mode="after")
    def _on_the_floor(self) -> BodyPlacement:
        if max(abs(self.position[0]), abs(self.position[1])) > 1e5:
            raise ValueError("position: metres from the origin, at most 100 km")
        return self


class InstanceConstraint(Strict):
    """Hard: the output at ``time_s`` comes from a given instance (the paper's illegal cells).

    Name it by ``instance`` (an id from a previous report) or by a target clip frame
    (``clip`` + ``clip_frame`` at the database rate, mapped to its instance's representative)."""

    time_s: float = Field(ge=0)
    instance: int | None = Field(default=None, ge=0)
    clip: str | None = None
    clip_frame: int | None = Field(default=None, ge=0)

    @model_validator(mode="after")
    def _one(self) -> InstanceConstraint:
        by_clip = self.clip is not None and self.clip_frame is not None
        if (self.instance is None) == (not by_clip):
            raise ValueError("give either 'instance' or both 'clip' and 'clip_frame'")
        return self


class ControlRequest(JobRequestBase):
    """A target motion driven by a control motion.

    Example: ``{"engine": "control", "control": {"bvh": "60_12_scaled.bvh"}}`` or
    ``{"engine": "control", "control": {"trajectory": {"fps": 30, "points": [[0, 0], [0.04, 0]]}}}``.
    Costs: interpretation D in m²·s (mean over points, integrated over time), continuity C in m²
    (mean over points) weighted by ``k`` (seconds)."""

    engine: Literal["control"] = "control"
    control: ControlInput
    k: float | None = Field(
        default=None,
        ge=0,
        le=1e6,
        description="continuity weight (seconds); default 0.1 for databases of control motions "
        "(dance: lowest leave-one-out follower error on the CMU salsa couples), 0.2 for walks driven "
        "by a path",
    )
    stretch_s: float | None = Field(
        default=None,
        ge=0,
        le=5,
        description="allowed uniform stretch of a segment, +- seconds (default 0.15)",
    )
    stretch_ratio: float | None = Field(
        default=None, ge=0, le=0.9, description="or +- this fraction of the segment's length"
    )
    continuity_s: float = Field(
        default=0.0,
        ge=0,
        le=2,
        description="continuity also compares the target this long before each boundary (velocity); "
        "0 = one frame (the paper)",
    )
    context_s: float = Field(
        default=0.0,
        ge=0,
        le=5,
        description="also compare this much control motion before and after each segment (0 = the paper)",
    )
    alignment: Literal["floor", "rigid"] = Field(
        default="floor",
        description="how a segment is aligned to the control: 'floor' = rotation about the vertical + "
        "floor translation (closed form; the paper's), 'rigid' = full 3-D rigid transform (Procrustes; "
        "about 30x slower preparation; may tilt or lift the target, e.g. for controls not on a level floor)",
    )
    solve_fps: float = Field(default=10.0, ge=1, le=240, description="rate of the downsampled solve")
    beam: float | None = Field(
        default=None,
        ge=0,
        description="beam width relative to a typical segment cost; omit for the anytime schedule "
        "(narrow beam, wider beam, then the exact optimum)",
    )
    exact: bool = Field(default=True, description="finish the anytime schedule with the exact optimum")
    constraints: list[InstanceConstraint] = Field(default_factory=list, max_length=1000)
    bodies: list[BodyPlacement] = Field(
        default_factory=list,
        max_length=1000,
        description="where the target's body stands at given times (e.g. a follower's start and end "
        "spots, which a leader's motion does not say); each is a soft cost in the search, then met "
        "within the examples' speed limits and reported as body[i]",
    )
    body_weight: float = Field(
        default=1.0,
        ge=0,
        le=1e6,
        description="seconds: weight of a placement's squared distance (m^2) against the interpretation "
        "distance (m^2 x s)",
    )
    smoothing_s: float = Field(default=0.15, ge=0, le=2, description="blend half-width across boundaries")
    footskate: bool = Field(default=True, description="clean up foot skate where a cleanup is available")
    feet: FeetMode | None = Field(default=None, description=FEET_DESCRIPTION)

    def feet_mode(self) -> FeetMode:
        """The clean-up this request asks for (:func:`schemas.common.feet_mode_of`)."""
        return feet_mode_of(self.footskate, self.feet)

    hold_hands: bool = Field(
        default=True,
        description="where the chosen examples hold hands, put the output's hand on the control's hand "
        "(arm IK; dance databases)",
    )

    @model_validator(mode="after")
    def _stretch(self) -> ControlRequest:
        if self.stretch_s is not None and self.stretch_ratio is not None:
            raise ValueError("give at most one of 'stretch_s' or 'stretch_ratio'")
        return self

    def named_clip_frames(self) -> list[tuple[str, str, int]]:
        return [
            (f"constraints[{k}]", c.clip, c.clip_frame)
            for k, c in enumerate(self.constraints)
            if c.clip is not None and c.clip_frame is not None
        ]

    def input_files(self) -> list[str]:
        """The control BVH, when the control is a motion."""
        return [self.control.bvh] if self.control.bvh is not None else []


# --------------------------------------------------------------------------- live control session


class ControlSessionPose(Strict):
    """Leader frames (a motion database): per frame the control joints' world positions, metres,
    Y up, in the order the session's first message names (``control_joints``), at its ``fps``."""

    type: Literal["pose"]
    frames: list[list[tuple[float, float, float]]] = Field(min_length=1, max_length=240)


class ControlSessionPath(Strict):
    """Path points (a walk database), e.g. from a game pad: ``[x, z]`` metres per frame at the
    session's ``fps``."""

    type: Literal["path"]
    points: list[tuple[float, float]] = Field(min_length=1, max_length=240)


class ControlSessionStop(Strict):
    """The control has ended: the server sends the remaining frames, ``{"type": "end"}``, closes."""

    type: Literal["stop"]


ControlSessionMessage = Annotated[
    ControlSessionPose | ControlSessionPath | ControlSessionStop, Field(discriminator="type")
]
