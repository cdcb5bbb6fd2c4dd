"""Annotation engine (Arikan, Forsyth & O'Brien 2003): database spec and request.

Database (``kind: "annotated"``): clips, some carrying label ranges (``labels`` of each clip, source
frames ``[start, end)``); the others are labelled by one RBF SVM per label trained on the labelled
frames (label propagation). A request paints a timeline: for every output frame and label, 1 (do),
-1 (don't) or 0 (don't care, the default); the search assembles database blocks whose labels match
it while staying continuous.

Label semantics of a spec: a ``value: 1`` range says "these frames do this, and do none of the other
labels of the vocabulary unless another range says so" (a labelled frame is fully annotated); a
``value: -1`` range only says "these frames do not do this label". Frames no range covers are
classified by the SVMs.
"""

from __future__ import annotations

import itertools
from typing import Literal

from pydantic import Field, model_validator

from .bases import DatabaseSpecBase, JobRequestBase
from .clips import LabelRange
from .common import FEET_DESCRIPTION, FeetMode, Strict, feet_mode_of


class AnnotatedDatabaseSpec(DatabaseSpecBase):
    """Annotated database: labelled and unlabelled clips; labels propagate by SVM.

    Example: ``{"kind": "annotated", "clips": [{"bvh": "a.bvh", "labels": [{"label": "walk",
    "start": 0, "end": 120}]}, {"bvh": "b.bvh"}]}``.
    """

    kind: Literal["annotated"] = "annotated"
    fps: float | None = Field(default=30.0, ge=1, le=1000, description="database rate (blocks are frames)")
    window_s: float = Field(
        default=1.0, gt=0, le=10, description="SVM embedding: joint positions over this window (s)"
    )
    window_samples: int = Field(default=7, ge=1, le=61, description="time samples of the SVM window")
    context_s: float = Field(
        default=4.0,
        ge=0,
        le=20,
        description="SVM embedding: coarse context window around the frame (s; 0 = none)",
    )
    context_samples: int = Field(default=9, ge=0, le=61, description="time samples of the context window")
    refine_changes: bool = Field(
        default=True,
        description="re-locate each label change within a clip with fine-window-only SVMs "
        "(within half the context window)",
    )
    svm_joints: list[str] | None = Field(
        default=None,
        min_length=1,
        description="joints of the SVM embedding (default: head, hands, elbows, feet, knees, chest)",
    )
    svm_c: float = Field(default=100.0, gt=0, le=1e6, description="SVM out-of-margin cost (kept high)")
    gammas: list[float] = Field(
        default_factory=lambda: [0.25, 0.5, 1.0, 2.0],
        min_length=1,
        max_length=10,
        description="RBF gamma grid, multiples of 1/(embedding dimension); chosen by cross-validation",
    )
    cv_folds: int = Field(default=3, ge=2, le=10, description="cross-validation folds (grouped by clip)")
    max_train_frames: int = Field(
        default=2000, ge=100, le=100_000, description="frames per label the SVM trains on (subsampled)"
    )
    smooth_s: float = Field(
        default=0.2, ge=0, le=5, description="moving average of SVM decision values before the sign (s)"
    )
    exclusive: bool = Field(
        default=True,
        description="labels never annotated together exclude each other (each frame: best allowed set)",
    )
    switch_s: float = Field(
        default=1.0,
        ge=0,
        le=30,
        description="with exclusive: cost of a label change within a clip (s of unit margin; 0 = none)",
    )
    self_training: int = Field(
        default=1, ge=0, le=5, description="self-training rounds on the confidently propagated frames"
    )
    predict_step_s: float = Field(
        default=0.1, ge=0, le=1, description="classify frames this far apart, interpolate in between (s)"
    )
    pca_dims: int = Field(default=20, ge=2, le=200, description="continuity features (PCA dimension)")
    block_sizes: list[int] = Field(
        default_factory=lambda: [32, 16, 8], min_length=1, max_length=6, description="search levels, frames"
    )
    coarse_clusters: int = Field(default=100, ge=1, le=5000, description="k-means clusters of top blocks")
    blocks_per_cluster: int = Field(
        default=100, ge=2, le=10_000, description="finer levels: about this many blocks per cluster"
    )
    label_weight: float = Field(
        default=1.0, ge=0, le=100, description="weight of the labels in the block clustering embedding"
    )
    seed: int = Field(default=0, ge=0, le=2**32 - 1, description="random state of the build")
    mirror: bool = Field(
        default=False,
        description="add the mirror image of every clip (left and right exchanged), named "
        "'<clip> (mirror)', with its clip's labels, a side a label names exchanged "
        "('wave-left-hand' -> 'wave-right-hand')",
    )

    @model_validator(mode="after")
    def _levels(self) -> AnnotatedDatabaseSpec:
        bs = self.block_sizes
        if any(b < 1 for b in bs):
            raise ValueError("block_sizes must be positive frame counts")
        for a, b in itertools.pairwise(bs):
            if b >= a or a % b:
                raise ValueError(f"block_sizes must decrease, each dividing the previous one; got {bs}")
        if any(g <= 0 for g in self.gammas):
            raise ValueError("gammas must be positive")
        return self


class TimelineEntry(Strict):
    """Output frames ``[start, end)`` should (1), should not (-1) or may (0) carry ``label``."""

    label: str = Field(min_length=1, max_length=64)
    start: int = Field(ge=0)
    end: int = Field(gt=0)
    value: Literal[1, 0, -1] = 1

    @model_validator(mode="after")
    def _ordered(self) -> TimelineEntry:
        if self.end <= self.start:
            raise ValueError(f"timeline {self.label!r}: end ({self.end}) must be after start ({self.start})")
        return self


class FrameConstraint(Strict):
    """Hard: output frame ``frame`` is frame ``clip_frame`` of database clip ``clip``."""

    frame: int = Field(ge=0, description="output frame")
    clip: str = Field(min_length=1, description="clip name as in the database spec")
    clip_frame: int = Field(ge=0, description="frame of that clip (database rate)")


class Placement(Strict):
    """Where the body starts: floor position ``[x, z]`` metres and facing (degrees about +Y)."""

    position: tuple[float, float] = (0.0, 0.0)
    heading_deg: float = 0.0


class EndConstraint(Strict):
    """Where the body should end: floor position ``[x, z]`` metres and optionally its facing.

    Soft: costs ``weight * 10 * (distance / 0.3 m + heading error / 10 deg)``; one unit is one
    output frame missing one requested label (times ``alpha``)."""

    position: tuple[float, float]
    heading_deg: float | None = None
    weight: float = Field(default=1.0, ge=0, le=1000)


DEFAULT_PASSES = 80
"""Coarse-to-fine passes of an annotation search by default (``bench/convergence.py``)."""
MAX_PASSES = 10_000


class AnnotationRequest(JobRequestBase):
    """A motion following a do / don't / don't-care label timeline.

    Example: ``{"engine": "annotations", "frames": 450, "timeline": [{"label": "walk", "start": 0,
    "end": 200, "value": 1}, {"label": "run", "start": 200, "end": 450, "value": 1},
    {"label": "wave-right-hand", "start": 0, "end": 450, "value": -1}], "seed": 3}``.
    """

    engine: Literal["annotations"] = "annotations"
    frames: int = Field(ge=2, le=100_000, description="output length in frames (database rate)")
    timeline: list[TimelineEntry] = Field(default_factory=list, max_length=1000)
    alpha: float = Field(
        default=0.5, ge=0, le=1, description="objective alpha * sum D + (1 - alpha) * sum C (paper Eq. 1)"
    )
    frame_constraints: list[FrameConstraint] = Field(default_factory=list, max_length=100)
    start: Placement = Field(default_factory=Placement)
    end: EndConstraint | None = None
    smoothing_frames: int = Field(default=8, ge=0, le=120, description="displacement smoothing half-width")
    refine_frames: int = Field(default=4, ge=0, le=16, description="boundary refinement search half-width")
    active_per_cluster: int = Field(
        default=100, ge=1, le=2000, description="finer levels: blocks of the parent's cluster tried per slot"
    )
    pool_size: int = Field(
        default=20, ge=1, le=100, description="best motions kept per level (end constraint)"
    )
    passes: int = Field(
        default=DEFAULT_PASSES,
        ge=1,
        le=MAX_PASSES,
        description="the search's work: coarse-to-fine DP passes, each from a fresh random active set "
        "(the best is kept); with a seed the same passes give the same motion on any machine and load",
    )
    confidence: bool = Field(
        default=True,
        description=(
            "D counts propagated labels by the SVM's confidence (decision value clipped to [-1, 1]; "
            "user-given labels count +-1); false: the paper's signs"
        ),
    )
    footskate: bool = Field(default=True, description="remove foot skate from the result (motion.footskate)")
    feet: FeetMode | None = Field(default=None, description=FEET_DESCRIPTION)

    def feet_mode(self) -> FeetMode:
        """The clean-up this request asks for (:func:`schemas.common.feet_mode_of`)."""
        return feet_mode_of(self.footskate, self.feet)

    loop: bool = Field(
        default=False,
        description="a looping clip: the end is blended so the last pose is the first (root travel "
        "continues; motion.looping); the report's 'loop' constraint measures it",
    )

    def named_labels(self) -> list[tuple[str, str, bool]]:
        """Every timeline label: the engine paints each on its vocabulary's columns, so each must
        be one of the database's labels (:meth:`JobRequestBase.named_labels`)."""
        return [(f"timeline[{k}]", e.label, True) for k, e in enumerate(self.timeline)]

    def named_clip_frames(self) -> list[tuple[str, str, int]]:
        return [
            (f"frame_constraints[{k}]", c.clip, c.clip_frame) for k, c in enumerate(self.frame_constraints)
        ]

    @model_validator(mode="after")
    def _inside(self) -> AnnotationRequest:
        for e in self.timeline:
            if e.end > self.frames:
                raise ValueError(
                    f"timeline {e.label!r} ends at {e.end}, after the motion's last frame ({self.frames})"
                )
        seen: set[int] = set()
        for c in self.frame_constraints:
            if c.frame >= self.frames:
                raise ValueError(f"frame constraint at frame {c.frame} is outside the motion ({self.frames})")
            if c.frame in seen:
                raise ValueError(f"two frame constraints at output frame {c.frame}")
            seen.add(c.frame)
        return self


class LabelCorrection(Strict):
    """One step of the correction loop on a built database.

    ``action: "set"``: frames ``[start, end)`` of ``clip`` do (``value`` 1) or do not (-1) carry
    ``label`` (replaces that label's ranges there). ``action: "accept"``: the propagated labels of
    those frames are right; they become explicit (every label of the vocabulary, 1 and -1)."""

    clip: str = Field(min_length=1)
    start: int = Field(ge=0)
    end: int = Field(gt=0)
    action: Literal["set", "accept"] = "set"
    label: str | None = Field(default=None, min_length=1, max_length=64)
    value: Literal[1, -1] = 1

    @model_validator(mode="after")
    def _valid(self) -> LabelCorrection:
        if self.end <= self.start:
            raise ValueError(
                f"correction on {self.clip!r}: end ({self.end}) must be after start ({self.start})"
            )
        if self.action == "set" and self.label is None:
            raise ValueError("a 'set' correction names its 'label'")
        return self


class ClipLabels(Strict):
    """The labels of one clip of an annotated database as ranges (database frames): every
    vocabulary label, +1 or -1, the user's where given and the SVMs' elsewhere
    (``GET /v1/databases/{id}/labels``)."""

    clip: str = Field(description="the clip, as asked for")
    frames: int = Field(ge=0, description="the clip's length, database frames")
    labels: list[LabelRange]
