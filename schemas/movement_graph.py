"""A rhythm database's movement transition graph and the choreographer's edits of it (Kim, Park &
Shin 2003, Sec. 4.3 "Refinement").

``GET /v1/databases/{id}/graph`` answers a :class:`MovementGraph`; ``POST
/v1/databases/{id}/graph-edits`` takes :class:`GraphEdits` and answers the derived database, whose
:class:`DerivedFrom` records its parent and the edits (resolved to group ids). ``segue graph`` and
``segue graph-edit`` read and write the same JSON.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .common import Strict


class ClipSpan(Strict):
    """A stretch of an example clip, naming the group of the basic movement that holds it: the
    movement (of the clip as danced, not its mirror image) that overlaps the span the most; a single
    instant (start = end) names the movement it falls in (a beat between two belongs to the later)."""

    clip: str = Field(min_length=1, max_length=128, description="the clip's name in the database")
    frames: tuple[int, int] | None = Field(
        default=None, description="[start, end] database frames (start = end: one frame)"
    )
    seconds: tuple[float, float] | None = Field(
        default=None,
        description="[start, end] seconds from the clip's first frame (start = end: one instant)",
    )

    @model_validator(mode="after")
    def _one_range(self) -> ClipSpan:
        given = [r for r in (self.frames, self.seconds) if r is not None]
        if len(given) != 1:
            raise ValueError(f"a clip span of {self.clip!r} gives exactly one of 'frames' or 'seconds'")
        lo, hi = given[0]
        if lo < 0 or hi < lo or hi > 1e7:
            raise ValueError(f"a clip span of {self.clip!r} needs 0 <= start <= end, not [{lo}, {hi}]")
        return self


GroupRef = Annotated[
    int | ClipSpan,
    Field(description="a group id, or a clip span naming the group of the movement that holds it"),
]


class GraphEdit(Strict):
    """One edit of the movement transition graph.

    * ``connect``: add the transition ``source -> target`` (it must not exist). Its likelihood is
      ``weight`` (default 1) times the mean likelihood of ``source``'s transitions at that point:
      with weight 1 it is as likely as an average transition out of ``source``.
    * ``cut``: remove the transition (it must exist); no ``weight``.
    * ``weight``: multiply the transition's likelihood by ``weight`` (it must exist).

    Edits apply in order; each row is then normalized again (probabilities out of a group sum to 1).
    """

    op: Literal["connect", "cut", "weight"]
    source: GroupRef
    target: GroupRef
    weight: float | None = Field(default=None, gt=0, le=1e6, description="a positive, finite factor")

    @model_validator(mode="after")
    def _weight(self) -> GraphEdit:
        if self.op == "weight" and self.weight is None:
            raise ValueError("a 'weight' edit gives its 'weight'")
        if self.op == "cut" and self.weight is not None:
            raise ValueError("a 'cut' edit takes no 'weight'")
        return self


class GraphEdits(Strict):
    """The body of ``POST /v1/databases/{id}/graph-edits`` (and the file of ``segue graph-edit``)."""

    edits: list[GraphEdit] = Field(min_length=1, max_length=1000)
    name: str | None = Field(default=None, max_length=128, description="a name for the derived database")


class ResolvedEdit(Strict):
    """An edit with its groups resolved to ids (``weight`` 1 made explicit on ``connect``): the
    canonical form a derived database's content address is computed from."""

    op: Literal["connect", "cut", "weight"]
    source: int = Field(ge=0)
    target: int = Field(ge=0)
    weight: float | None = None


class DerivedFrom(Strict):
    """Where a derived database comes from: its parent's id and the edits applied to it."""

    parent: str
    edits: list[ResolvedEdit]


class RepresentativeSpan(Strict):
    """The group's representative movement (its medoid) as a stretch of an example clip."""

    clip: str = Field(description="the clip's name in the database (its spec name, else its file stem)")
    mirrored: bool = Field(description="the movement comes from the clip's mirror image (spec 'mirror')")
    start_frame: int = Field(description="database frames")
    end_frame: int
    start_s: float
    end_s: float


class GraphGroup(Strict):
    """A node: a group of basic movements."""

    id: int
    size: int = Field(description="basic movements in the group")
    start_probability: float = Field(description="pi: likelihood that a dance starts with this group")
    representative: RepresentativeSpan
    pose: list[list[float]] = Field(
        description="(J, 3) joint positions (metres, Y up, facing +Z, body root above the origin) at "
        "the middle frame of the representative movement: a thumbnail"
    )
    pose_frame: int = Field(description="the pose's database frame in the representative clip")


class GraphTransition(Strict):
    """An edge ``source -> target`` of the graph synthesis walks."""

    source: int
    target: int
    probability: float = Field(
        description="P(target | source): what synthesis draws with (beat-clarity preference included), "
        "at a tempo that allows every movement; faster music avoids the movements too fast for it"
    )
    kinematic: float = Field(description="P_k: kinematic likelihood (end/start posture continuity, Eq. 22)")
    behavioural: float = Field(description="P_b: behavioural likelihood (observed in the examples, Eq. 26)")
    learned: bool = Field(description="the transition was in the graph learned from the examples")


class MovementGraph(Strict):
    """The movement transition graph of a ready rhythm database (``GET /v1/databases/{id}/graph``)."""

    database: str
    fps: float
    beats_per_movement: int
    kinematic_weight: float | None = Field(
        description="w1 of the learned graph P = w1 P_k + (1 - w1) P_b (edges at or below "
        "edge_threshold dropped, rows normalized)"
    )
    joints: list[str]
    parents: list[int]
    groups: list[GraphGroup]
    transitions: list[GraphTransition]
    strongly_connected: bool = Field(description="every group can be reached from every other")
    start_only_groups: list[int] = Field(
        default_factory=list,
        description="groups a dance is in only by starting there (or in their own strongly connected "
        "part): no other group leads to them",
    )
    unreachable_groups: list[int] = Field(
        default_factory=list,
        description="groups no dance is ever in (not a start group, and no group leads to them)",
    )
    derived_from: DerivedFrom | None = None
