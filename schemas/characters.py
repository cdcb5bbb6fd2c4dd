"""Characters in a viewer: a source skeleton to bind a character to, and the binding the service
computes (``POST /v1/characters/binding``) or the character's model (``POST /v1/characters/model``).

A character is an uploaded glTF/GLB file (its first skin and mesh), an uploaded BVH clip (its
skeleton, worn by Segue's mannequin) or, when none is named, Segue's mannequin made on the source
skeleton itself. Lengths are metres, rotations unit quaternions ``(x, y, z, w)``, Y up.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, Field

from .common import Strict

MAX_JOINTS = 1024
"""Most joints (End Sites included) of a source skeleton."""
MAX_EXAMPLE_FRAMES = 240
"""Most example frames a binding request carries (a viewer sends at most 240, evenly spaced)."""

Metres = Annotated[float, Field(ge=-1e4, le=1e4)]
Unit = Annotated[
    float, Field(ge=-2.0, le=2.0, description="a quaternion component (normalized by the service)")
]
Vec3 = tuple[Metres, Metres, Metres]
Quat = tuple[Unit, Unit, Unit, Unit]


class EndSite(Strict):
    """A leaf marker without a rotation (a BVH End Site): where a bone ends."""

    parent: int = Field(ge=0, description="the joint it hangs from (index into names)")
    offset: Vec3 = Field(description="from the parent joint, metres, in the parent's frame")


class SourceSkeleton(Strict):
    """The skeleton motion arrives on (a result, a clip, a live session), as the viewer draws it."""

    names: list[str] = Field(min_length=1, max_length=MAX_JOINTS, description="joint names, unique")
    parents: list[int] = Field(max_length=MAX_JOINTS, description="parent index per joint, -1 for joint 0")
    offsets: list[Vec3] = Field(max_length=MAX_JOINTS, description="rest translation from the parent, metres")
    end_sites: list[EndSite] = Field(default_factory=list, max_length=MAX_JOINTS)


class ExampleFrames(Strict):
    """Frames of motion on the source skeleton: what the retargeting measures on a whole motion
    (the hip-height ratio, the floor, how a planted foot lies) is measured on them."""

    fps: float = Field(gt=0, le=1000, description="their frame rate")
    root: list[Vec3] = Field(
        min_length=2, max_length=MAX_EXAMPLE_FRAMES, description="joint 0's position per frame, metres"
    )
    rotations: list[list[Quat]] = Field(
        min_length=2, max_length=MAX_EXAMPLE_FRAMES, description="per frame, every joint's local rotation"
    )


class CharacterRequest(Strict):
    """A character and the skeleton it is to follow."""

    character: str | None = Field(
        default=None,
        max_length=255,
        description="an uploaded glTF/GLB file or BVH clip (id or name); none: Segue's mannequin "
        "made on the skeleton",
    )
    skeleton: SourceSkeleton
    example: ExampleFrames | None = Field(default=None, description="frames to measure the retargeting on")


class CharacterOf(BaseModel):
    """Which character a binding or a model is of."""

    kind: str = Field(description="file (glTF/GLB), clip (a BVH skeleton on the mannequin) or mannequin")
    id: str | None = Field(default=None, description="the upload's id")
    name: str = Field(description="as uploaded, or 'mannequin'")


class BoundJoint(BaseModel):
    """A character joint that follows a source joint: its world rotation is the source joint's
    world rotation times ``offset``."""

    joint: str
    source: str
    offset: tuple[float, float, float, float]


class BoundHips(BaseModel):
    """Where the character's hips go: the source's hips, floor position times ``scale``, height
    ``target_floor + scale * (y - source_floor)``."""

    joint: str
    source: str
    scale: float
    source_floor: float = Field(description="the source's standing ankle height, metres")
    target_floor: float = Field(description="the character's standing ankle height, metres")


class CharacterBinding(BaseModel):
    """How a character follows the source skeleton frame by frame (:mod:`motion.retarget.binding`):
    joints not listed keep their rest rotation relative to their parent."""

    character: CharacterOf
    source: list[str] = Field(description="the source skeleton's joint names")
    target: list[str] = Field(description="the character's skin joint names")
    joints: list[BoundJoint]
    hips: BoundHips
