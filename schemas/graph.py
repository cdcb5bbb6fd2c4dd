"""Requests of the motion-graph engine: length and constraints (Arikan & Forsyth 2002, Sec. 3.2).

Times are output frames at the database rate (``frame``) or seconds (``time_s``); floor positions
are ``[x, z]`` metres, heights ``y`` metres; ``heading_deg`` is the facing about +Y (0 = +Z, 90 = +X).
The score weights follow the paper: an error of 10 frames, of 30 cm and of 10 degrees cost the same.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, model_validator

from .bases import JobRequestBase
from .common import FEET_DESCRIPTION, FeetMode, Strict, feet_mode_of


class _Timed(Strict):
    frame: int | None = Field(default=None, ge=0, description="output frame (database rate)")
    time_s: float | None = Field(default=None, ge=0, description="or the time in seconds")
    weight: float = Field(default=1.0, ge=0, le=1000)

    @model_validator(mode="after")
    def _one_time(self) -> _Timed:
        if (self.frame is None) == (self.time_s is None):
            raise ValueError("give exactly one of 'frame' or 'time_s'")
        return self


class BodyConstraint(_Timed):
    """The body (root on the floor, facing) at a position and heading at a time; the first one
    places the motion."""

    type: Literal["body"] = "body"
    position: tuple[float, float] = Field(description="[x, z] metres")
    heading_deg: float | None = Field(default=None, description="facing; omit to leave it free")


class JointConstraint(_Timed):
    """A joint at a position (and optionally moving with a velocity) at a time."""

    type: Literal["joint"] = "joint"
    joint: str
    position: tuple[float, float, float] = Field(description="[x, y, z] metres")
    velocity: tuple[float, float, float] | None = Field(default=None, description="m/s")


class PoseConstraint(_Timed):
    """Hard: the output frame at this time is a given clip frame."""

    type: Literal["pose"] = "pose"
    clip: str = Field(description="clip name as in the database spec")
    clip_frame: int = Field(ge=0, description="frame of that clip (database rate)")


class LabelConstraint(Strict):
    """Frames ``[start, end)`` of the output should (value 1) or should not (-1) carry a label."""

    type: Literal["label"] = "label"
    label: str
    start: int = Field(ge=0)
    end: int = Field(gt=0)
    value: Literal[1, -1] = 1
    weight: float = Field(default=1.0, ge=0, le=1000)


class Disc(Strict):
    center: tuple[float, float]
    radius: float = Field(gt=0)


class ObstacleConstraint(Strict):
    """A region of the floor the root and the feet must stay out of: a disc or a polygon."""

    type: Literal["obstacle"] = "obstacle"
    disc: Disc | None = None
    polygon: list[tuple[float, float]] | None = Field(default=None, min_length=3)
    weight: float = Field(default=1.0, ge=0, le=1000)

    @model_validator(mode="after")
    def _one_shape(self) -> ObstacleConstraint:
        if (self.disc is None) == (self.polygon is None):
            raise ValueError("an obstacle is exactly one of 'disc' or 'polygon'")
        return self


Constraint = Annotated[
    BodyConstraint | JointConstraint | PoseConstraint | LabelConstraint | ObstacleConstraint,
    Field(discriminator="type"),
]


class Point(Strict):
    """A point of one character: a named joint, or its body (the hips' floor projection) when
    ``joint`` is omitted."""

    character: int = Field(ge=0, le=63, description="index into the request's 'characters'")
    joint: str | None = Field(default=None, description="joint name; omit for the body on the floor")


class MeetConstraint(_Timed):
    """Shared: point ``a`` of one character is ``distance_m`` from point ``b`` of another at a time
    (hands meeting: two joints and ``distance_m`` 0; passing each other: two bodies and the
    passing distance). Joint to joint is a 3-D distance; with a body the floor distance."""

    type: Literal["meet"] = "meet"
    a: Point
    b: Point
    distance_m: float = Field(default=0.0, ge=0, le=100, description="wanted distance, metres")
    tolerance_cm: float = Field(default=5.0, gt=0, le=10_000, description="met within this, cm")


class ApartConstraint(Strict):
    """Shared: points ``a`` and ``b`` of two characters stay at least ``min_m`` apart over output
    frames ``[start, end)`` (``end`` omitted: to the end of the motion). Bodies: floor distance;
    joints: 3-D distance."""

    type: Literal["apart"] = "apart"
    a: Point
    b: Point
    min_m: float = Field(gt=0, le=100, description="smallest allowed distance, metres")
    start: int = Field(default=0, ge=0)
    end: int | None = Field(default=None, gt=0)
    weight: float = Field(default=1.0, ge=0, le=1000)

    @model_validator(mode="after")
    def _range(self) -> ApartConstraint:
        if self.end is not None and self.end <= self.start:
            raise ValueError(f"'end' ({self.end}) must be after 'start' ({self.start})")
        return self


SharedConstraint = Annotated[MeetConstraint | ApartConstraint, Field(discriminator="type")]


class GraphCharacter(Strict):
    """One character of a several-character request: its own constraints (a body constraint at
    frame 0 is its start), as a one-character request's."""

    constraints: list[Constraint] = Field(default_factory=list, max_length=1000)


class GraphWeights(Strict):
    """Relative weights of the score terms (paper Eq. 1)."""

    continuity: float = Field(default=1.0, ge=0, description="sum of transition costs along the path")
    length: float = Field(default=1.0, ge=0)
    body: float = Field(default=1.0, ge=0)
    joint: float = Field(default=1.0, ge=0)
    label: float = Field(default=1.0, ge=0)
    obstacle: float = Field(default=1.0, ge=0)
    shared: float = Field(default=1.0, ge=0, description="constraints between characters")


DEFAULT_ROUNDS = 15
"""Search rounds of a graph request by default (``bench/convergence.py``)."""
MAX_ROUNDS = 100_000


class GraphRequest(JobRequestBase):
    """A motion of a given length meeting constraints, found by randomized search of the graph."""

    engine: Literal["graph"] = "graph"
    frames: int | None = Field(default=None, ge=2, le=100_000, description="output length in frames")
    seconds: float | None = Field(default=None, gt=0, le=3600, description="or in seconds")
    constraints: list[Constraint] = Field(default_factory=list, max_length=1000)
    alternatives: int = Field(default=1, ge=1, le=20, description="distinct local minima to return")
    rounds: int | None = Field(
        default=DEFAULT_ROUNDS,
        ge=0,
        le=MAX_ROUNDS,
        description="the search's work: at most this many rounds (it also stops when it converges, "
        "25 rounds without a better path; null: only then); with a seed the same request returns the "
        "same motion on every machine and load, from every face (CLI, HTTP, workers)",
    )
    characters: list[GraphCharacter] | None = Field(
        default=None,
        min_length=2,
        max_length=16,
        description="several characters, each with its own constraints, searched jointly with "
        "'shared' constraints (the top-level 'constraints' must then be empty)",
    )
    shared: list[SharedConstraint] = Field(
        default_factory=list, max_length=1000, description="constraints between two characters"
    )
    coupling_rounds: int = Field(
        default=3,
        ge=0,
        le=20,
        description="rounds of coordinate descent over the characters (engines.graph.coupled)",
    )
    weights: GraphWeights = Field(default_factory=GraphWeights)
    smoothing_frames: int = Field(default=15, ge=0, le=300, description="displacement smoothing half-width")
    footskate: bool = Field(
        default=True, description="pin planted feet with the source clips' contacts (motion.footskate)"
    )
    feet: FeetMode | None = Field(default=None, description=FEET_DESCRIPTION)

    def feet_mode(self) -> FeetMode:
        """The clean-up this request asks for (:func:`schemas.common.feet_mode_of`)."""
        return feet_mode_of(self.footskate, self.feet)

    loop: bool = Field(
        default=False,
        description="a looping clip: the end is blended so the last pose is the first (root travel "
        "continues; motion.looping); the report's 'loop' constraint measures it",
    )

    @model_validator(mode="after")
    def _length(self) -> GraphRequest:
        if (self.frames is None) == (self.seconds is None):
            raise ValueError("give exactly one of 'frames' or 'seconds'")
        if self.characters is None:
            if self.shared:
                raise ValueError("'shared' constraints need 'characters' (at least two)")
            return self
        if self.constraints:
            raise ValueError(
                "with 'characters', put each character's constraints in characters[i].constraints "
                "(the top-level 'constraints' must be empty)"
            )
        n = len(self.characters)
        for i, c in enumerate(self.shared):
            where = f"shared[{i}] ({c.type})"
            for side, p in (("a", c.a), ("b", c.b)):
                if p.character >= n:
                    raise ValueError(
                        f"{where}: {side}.character {p.character} is not one of the {n} characters "
                        f"(0..{n - 1})"
                    )
            if c.a.character == c.b.character:
                raise ValueError(f"{where}: 'a' and 'b' name the same character {c.a.character}")
            self._inside(where, c)
        return self

    def _inside(self, where: str, c: MeetConstraint | ApartConstraint) -> None:
        """A shared constraint's times fall inside the motion (when its length is in frames, or
        both are in seconds)."""
        n = self.frames
        if isinstance(c, MeetConstraint):
            if n is not None and c.frame is not None and c.frame >= n:
                raise ValueError(f"{where}: frame {c.frame} is past the motion's {n} frames (0..{n - 1})")
            if self.seconds is not None and c.time_s is not None and c.time_s > self.seconds:
                raise ValueError(f"{where}: time {c.time_s:g} s is past the motion's {self.seconds:g} s")
        elif n is not None and (c.start >= n or (c.end is not None and c.end > n)):
            raise ValueError(f"{where}: frames [{c.start}, {c.end}) are past the motion's {n} frames")

    def _constraint_lists(self) -> list[tuple[str, list[Any]]]:
        return [("", list(self.constraints))] + [
            (f"characters[{i}].", list(c.constraints)) for i, c in enumerate(self.characters or [])
        ]

    def named_labels(self) -> list[tuple[str, str, bool]]:
        """Label constraints: one asking for a label (value 1) needs a clip carrying it; one
        asking to avoid it may name any label (:meth:`JobRequestBase.named_labels`)."""
        return [
            (f"{prefix}constraints[{k}]", c.label, c.value == 1)
            for prefix, constraints in self._constraint_lists()
            for k, c in enumerate(constraints)
            if c.type == "label"
        ]

    def named_clip_frames(self) -> list[tuple[str, str, int]]:
        return [
            (f"{prefix}constraints[{k}]", c.clip, c.clip_frame)
            for prefix, constraints in self._constraint_lists()
            for k, c in enumerate(constraints)
            if c.type == "pose"
        ]

    def named_joints(self) -> list[tuple[str, str]]:
        """``(where, joint name)`` of every joint the request names (joint constraints, of each
        character too, and the points of shared constraints), to check against a database's
        skeleton at submission."""
        out: list[tuple[str, str]] = []
        lists = [("", self.constraints)] + [
            (f"characters[{i}].", c.constraints) for i, c in enumerate(self.characters or [])
        ]
        for prefix, constraints in lists:
            out += [
                (f"{prefix}constraints[{k}]", c.joint) for k, c in enumerate(constraints) if c.type == "joint"
            ]
        for k, c in enumerate(self.shared):
            out += [
                (f"shared[{k}].{side}", p.joint)
                for side, p in (("a", c.a), ("b", c.b))
                if p.joint is not None
            ]
        return out
