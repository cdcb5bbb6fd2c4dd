"""Requests of the motion-graph engine: length and constraints (Arikan & Forsyth 2002, Sec. 3.2).

Times are output frames at the database rate (``frame``) or seconds (``time_s``); floor positions
are ``[x, z]`` metres, heights ``y`` metres; ``heading_deg`` is the facing about +Y (0 = +Z, 90 = +X).
The score weights follow the paper: an error of 10 frames, of 30 cm and of 10 degrees cost the same.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .bases import JobRequestBase
from .common import Strict


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


class GraphWeights(Strict):
    """Relative weights of the score terms (paper Eq. 1)."""

    continuity: float = Field(default=1.0, ge=0, description="sum of transition costs along the path")
    length: float = Field(default=1.0, ge=0)
    body: float = Field(default=1.0, ge=0)
    joint: float = Field(default=1.0, ge=0)
    label: float = Field(default=1.0, ge=0)
    obstacle: float = Field(default=1.0, ge=0)


class GraphRequest(JobRequestBase):
    """A motion of a given length meeting constraints, found by randomized search of the graph."""

    engine: Literal["graph"] = "graph"
    frames: int | None = Field(default=None, ge=2, le=100_000, description="output length in frames")
    seconds: float | None = Field(default=None, gt=0, le=3600, description="or in seconds")
    constraints: list[Constraint] = Field(default_factory=list, max_length=1000)
    alternatives: int = Field(default=1, ge=1, le=20, description="distinct local minima to return")
    rounds: int | None = Field(
        default=None,
        ge=0,
        le=100_000,
        description="stop after this many search rounds (the search also stops when it converges); "
        "with a seed, a search that ends by rounds or convergence within its budget returns the same "
        "motion on every machine and from every face (CLI, HTTP)",
    )
    weights: GraphWeights = Field(default_factory=GraphWeights)
    smoothing_frames: int = Field(default=15, ge=0, le=300, description="displacement smoothing half-width")
    footskate: bool = Field(
        default=True, description="pin planted feet with the source clips' contacts (motion.footskate)"
    )
    loop: bool = Field(
        default=False,
        description="a looping clip: the end is blended so the last pose is the first (root travel "
        "continues; motion.looping); the report's 'loop' constraint measures it",
    )

    @model_validator(mode="after")
    def _length(self) -> GraphRequest:
        if (self.frames is None) == (self.seconds is None):
            raise ValueError("give exactly one of 'frames' or 'seconds'")
        return self
