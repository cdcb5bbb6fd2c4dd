"""Clips: uploaded motions, and references to them inside database specs."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime

from pydantic import Field, field_validator, model_validator

from .common import Strict


class LabelRange(Strict):
    """A label on a frame range ``[start, end)`` of a clip, in frames at the database rate (the
    spec's ``fps``, else the first clip's; not the file's own rate: a 120 fps clip in a 30 fps
    database has a quarter as many frames)."""

    label: str = Field(min_length=1, max_length=64)
    start: int = Field(ge=0, description="first frame, at the database rate")
    end: int = Field(gt=0, description="frame after the last, at the database rate")
    value: int = Field(default=1, description="+1 the label applies, -1 it does not")

    @model_validator(mode="after")
    def _ordered(self) -> LabelRange:
        if self.end <= self.start:
            raise ValueError(f"label {self.label!r}: end ({self.end}) must be after start ({self.start})")
        if self.value not in (-1, 1):
            raise ValueError("label value must be 1 or -1")
        return self


class ClipSource(Strict):
    """A clip inside a database spec.

    ``bvh`` names the motion: in a spec file for the CLI, a path relative to the spec file; through the
    API, the file name of an uploaded clip (or ``clip`` gives an uploaded clip's id); anywhere,
    ``sample:NAME`` for a bundled sample (``segue samples``). The file may be a glTF/GLB file with a
    skin and an animation (``animation`` picks one of several; ``segue inspect`` lists them). ``name``
    is how reports refer to the clip (default: the file name without ``.bvh``/``.glb``/``.gltf``, or
    the sample's NAME).
    """

    bvh: str | None = Field(
        default=None,
        min_length=1,
        max_length=1024,
        examples=["60_01_scaled.bvh"],
        description="the motion file: BVH (.bvh, .bvh.gz) or glTF with a skin and an animation (.glb, .gltf)",
    )
    clip: str | None = Field(default=None, description="id of an uploaded clip (API only)")
    animation: str | int | None = Field(
        default=None,
        description="which animation of a glTF clip, by name or index (default: its first); BVH: none",
    )
    name: str | None = Field(default=None, min_length=1, max_length=128)
    labels: list[LabelRange] = Field(default_factory=list)
    units: str | None = Field(default=None, description="declared length unit of the file (default: guessed)")

    @model_validator(mode="after")
    def _one_source(self) -> ClipSource:
        if (self.bvh is None) == (self.clip is None):
            raise ValueError(
                "give exactly one of 'bvh' (a file name or path) or 'clip' (an uploaded clip id)"
            )
        return self

    @field_validator("units")
    @classmethod
    def _known_units(cls, v: str | None) -> str | None:
        from motion.units import METRES_PER_UNIT

        if v is not None and v not in METRES_PER_UNIT:
            raise ValueError(f"unknown units {v!r}; use one of {', '.join(METRES_PER_UNIT)}")
        return v

    def display_name(self) -> str:
        if self.name:
            return self.name
        base = (self.bvh or self.clip or "clip").replace("\\", "/").rsplit("/", 1)[-1]
        base = base.removeprefix("sample:")
        for suffix in (".gz", ".bvh", ".glb", ".gltf"):
            base = base.removesuffix(suffix)
        return base


def labels_past_clip_end(clips: Sequence[ClipSource], frames: Sequence[int], fps: float) -> list[str]:
    """One message per label range that ends after its clip's last frame: ``frames`` are the clips'
    frame counts at the database rate ``fps`` (label ranges are in those frames)."""
    problems = []
    for i, (clip, count) in enumerate(zip(clips, frames, strict=True)):
        for k, lb in enumerate(clip.labels):
            if lb.end > count:
                problems.append(
                    f"clips[{i}] ({clip.display_name()}): labels[{k}] {lb.label!r} [{lb.start}, {lb.end}) "
                    f"ends after the clip, which has {count} frames at {fps:g} fps (frames 0-{count - 1})"
                )
    return problems


class AnimationInfo(Strict):
    """One animation of a glTF clip, as Segue reads it (:func:`motion.gltf.gltf_animations`)."""

    name: str
    frames: int
    fps: float


class ClipInfo(Strict):
    """An uploaded clip (stored once per content hash)."""

    id: str = Field(description="sha256 of the uploaded bytes")
    name: str = Field(description="file name given at upload")
    frames: int
    fps: float
    joints: list[str]
    units: str
    height_m: float = Field(
        description="standing height of the motion in metres (the median over frames of its vertical extent)"
    )
    size_bytes: int
    created_at: datetime
    format: str = Field(default="bvh", description="bvh, or gltf (a GLB or .gltf file's animation)")
    animations: list[AnimationInfo] = Field(
        default_factory=list,
        description="glTF: every animation of the file (a database spec's 'animation' picks one); "
        "the frames, rate and height above are of the first",
    )
    warnings: list[str] = Field(
        default_factory=list,
        description="what the file needed to be read (e.g. 'line 128: Frames: 3069, but the file holds 3070 "
        "frame lines: read 3070'): it was read, and these say how",
    )
