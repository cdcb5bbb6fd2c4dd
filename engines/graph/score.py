"""The score of a path (Arikan & Forsyth 2002, Eq. 1 and Sec. 4.2.1), for whole batches of paths.

``S = w_c sum cost(e) + w_f F + w_b B + w_j J + w_l L + w_o O``, every term dimensionless with the
paper's units: an error of **10 frames**, of **30 cm** and of **10 degrees** cost the same (1).

* ``continuity`` = sum of the transition costs of the edges whose cut lies inside the output,
  plus a penalty for pieces shorter than :data:`MIN_PIECE_S` between two cuts.
* ``length`` F = ``(missing frames / 10)^2``: a path that plays fewer frames than asked for (paths
  are truncated to the length, so a long enough path has F = 0 and the output is exact).
* ``body`` B: the first body constraint (in time) *places* the motion (so it is always met); each
  other one adds ``weight * ((distance / 0.30 m)^2 + (heading error / 10 deg)^2)`` (no heading
  term when its heading is free), where the errors are the corrections assembly will spread over
  the frames since the previous constraint (:mod:`engines.graph.fit`), plus ``(excess / 5 cm)^2``
  and ``(excess / 5 deg)^2`` for the part of them beyond the database's physical limits (which
  will not be delivered). When the first one leaves the heading free, the motion is turned
  about it so that it heads for the second body constraint.
* ``joint`` J: per joint constraint ``weight * ((distance / 0.30 m)^2 + (velocity error /
  0.30 m/s)^2)`` (velocity term only when given), from the library's joint positions; the floor
  part of the distance, which assembly corrects like a body constraint's, is charged as that
  correction (and its excess).
* ``label`` L: per label constraint ``weight * frames / 10``, counting the frames of its window
  that lack a wanted label (value 1) or carry an unwanted one (value -1), from the clips' labels.
* ``obstacle`` O: every ``step`` output frames (2 or more, at most 100 samples), the root and the
  feet are tested against each obstacle (disc or polygon on the floor, grown by a 5 cm margin for
  the frames between samples); a sample whose deepest point is ``d`` metres inside costs
  ``weight * (step / 10) * (1 + d / 0.30)^2``: 10 frames inside cost at least 1.

Hard pose constraints ("output frame t is clip c frame k") are not scored: paths that break them
are invalid (infinite score). The start frame of a path is re-anchored so that the first pose
constraint falls at its time (:func:`anchor_poses`); the later ones must then hold exactly.

Body positions and headings come from the root tracks (:class:`~engines.graph.model.RootTracks`),
placed by :mod:`engines.graph.paths`; the final errors are measured again on the assembled
motion (:mod:`engines.graph.assemble`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from motion import MotionError
from motion.contacts import foot_joints
from motion.regions import FloorRegion
from motion.rotations import rotate_floor, wrap_angle
from schemas.graph import GraphRequest

from ..base import EngineError
from ..library import MotionLibrary
from .fit import BatchFit, FitGrid, batch_fit, fit_grid
from .model import FloatArray, IntArray, RootTracks
from .paths import (
    BatchPieces,
    BoolArray,
    GraphIndex,
    JointTable,
    Path,
    PathBatch,
    Pieces,
    Placement,
    batch_pieces,
    batch_transforms,
    batch_valid,
    compose2,
    locate,
    path_pieces,
)

FRAMES_UNIT = 10.0
"""Frames that cost 1 (length, labels, time inside obstacles)."""
METRES_UNIT = 0.30
"""Metres that cost 1 (body and joint positions)."""
RADIANS_UNIT = float(np.radians(10.0))
"""Heading error that costs 1 (10 degrees)."""
VELOCITY_UNIT = 0.30
"""Joint velocity error (m/s) that costs 1."""
OBSTACLE_SAMPLES = 100
"""At most this many sampled output frames per path for obstacles (every 2 frames or more)."""
MIN_PIECE_S = 0.2
"""Pieces of motion between two cuts shorter than this (seconds) are penalised: two cuts a
frame or two apart jolt the body however well each one matches (the displacement smoothing of
one overlaps the other)."""
SHORT_PIECE_COST = 2.0
"""Penalty of a one-frame piece (twice a typical transition's cost), falling quadratically to 0
at :data:`MIN_PIECE_S`."""
EXCESS_METRES = 0.05
"""Body correction beyond what assembly's physical limits allow (it will not be delivered: the
goal stays missed by that much) costs 1 per 5 cm, the report's tolerance."""
EXCESS_RADIANS = float(np.radians(5.0))
"""Likewise for heading: 1 per 5 degrees beyond the limits."""
OBSTACLE_DEPTH_UNIT = 0.05
"""Obstacle depth (metres) that doubles a sample's cost (:data:`METRES_UNIT` is too lenient for
"stay out")."""
OBSTACLE_MARGIN = 0.05
"""Obstacles are grown by this much (metres) while searching, so that the frames between samples
stay out too (feet move a few centimetres per frame)."""

TERMS = ("continuity", "length", "body", "joint", "label", "obstacle", "shared")


@dataclass(frozen=True, slots=True)
class BodyTarget:
    """A body constraint: root at ``xz`` (metres) facing ``heading`` (radians, or free) at ``frame``."""

    name: str
    frame: int
    xz: FloatArray
    heading: float | None
    weight: float


@dataclass(frozen=True, slots=True)
class JointTarget:
    """A joint constraint; ``column`` indexes the problem's :class:`JointTable`."""

    name: str
    frame: int
    joint: int
    column: int
    position: FloatArray
    velocity: FloatArray | None
    weight: float


@dataclass(frozen=True, slots=True)
class PoseTarget:
    """Hard: output ``frame`` is frame ``clip_frame`` of clip ``clip``."""

    name: str
    frame: int
    clip: int
    clip_frame: int


@dataclass(frozen=True, slots=True)
class LabelTarget:
    """Frames ``[start, end)`` should carry (``value`` 1) or not carry (-1) ``label``; ``good`` is
    the ``(N + 1,)`` running count of library frames that satisfy it (concatenated clips)."""

    name: str
    label: str
    start: int
    end: int
    value: int
    weight: float
    good: IntArray


@dataclass(frozen=True, slots=True)
class ObstacleTarget:
    """An obstacle: a floor region (:class:`motion.regions.FloorRegion`) the root and feet avoid."""

    name: str
    weight: float
    region: FloorRegion

    def depth(self, points: FloatArray, margin: float = 0.0) -> FloatArray:
        """How far (metres) floor points ``(..., 2)`` are inside the region grown by ``margin``."""
        return self.region.depth(points, margin)


@dataclass(frozen=True, slots=True)
class KeepawayTarget:
    """A moving keep-out disc: the character's body (``joint`` None) or the floor position of
    output joint ``joint`` stays ``radius`` metres from ``track (T, 2)`` (a floor point per
    output frame, metres) over output frames ``[start, end)``; ``column`` indexes the problem's
    :class:`JointTable` for a joint (-1 for the body)."""

    name: str
    weight: float
    joint: int | None
    track: FloatArray
    radius: float
    start: int
    end: int
    column: int = -1


@dataclass(frozen=True)
class Problem:
    """A request compiled against a database: every time in output frames, every clip and joint
    by index, constraints in request order within each kind (their names: ``body[0]``...)."""

    length: int
    fps: float
    weights: dict[str, float]
    bodies: tuple[BodyTarget, ...] = ()
    joints: tuple[JointTarget, ...] = ()
    poses: tuple[PoseTarget, ...] = ()
    labels: tuple[LabelTarget, ...] = ()
    obstacles: tuple[ObstacleTarget, ...] = ()
    keepaways: tuple[KeepawayTarget, ...] = ()
    table: JointTable | None = None
    foot_columns: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    grid: FitGrid | None = None

    @property
    def placed_by(self) -> BodyTarget | None:
        """The body constraint that places the motion (the earliest)."""
        return self.bodies[0] if self.bodies else None


def _frame_of(c: Any, fps: float) -> int:
    return int(c.frame) if c.frame is not None else round(float(c.time_s) * fps)


def compile_problem(
    request: GraphRequest,
    library: MotionLibrary,
    tracks: RootTracks,
    keepaways: tuple[KeepawayTarget, ...] = (),
) -> Problem:
    """Check a :class:`schemas.graph.GraphRequest` against the database and compile it, with the
    ``keepaways`` a coupled search derives from other characters (:mod:`engines.graph.coupled`).

    Raises :class:`~engines.base.EngineError` for constraints the database cannot serve: times
    outside the output, unknown clips, joints or labels, clip frames out of range, or two pose
    constraints at one time.
    """
    fps = library.fps
    length = (
        int(request.frames) if request.frames is not None else max(round((request.seconds or 0.0) * fps), 2)
    )
    w = request.weights
    weights = {
        "continuity": float(w.continuity),
        "length": float(w.length),
        "body": float(w.body),
        "joint": float(w.joint),
        "label": float(w.label),
        "obstacle": float(w.obstacle),
        "shared": float(w.shared),
    }
    targets = _Targets(library, tracks, length)
    for c in request.constraints:
        targets.add(c)
    poses = sorted(targets.poses, key=lambda p: p.frame)
    for a, b in itertools.pairwise(poses):
        if a.frame == b.frame and (a.clip, a.clip_frame) != (b.clip, b.clip_frame):
            raise EngineError(f"{a.name} and {b.name} ask for different poses at output frame {a.frame}")
    bodies = sorted(targets.bodies, key=lambda b: b.frame)
    obstacles = targets.obstacles
    for k in keepaways:
        if k.track.shape != (length, 2):
            raise EngineError(f"{k.name}: a track of {k.track.shape[0]} frames for a {length}-frame motion")
    tracked = [j for _, _, j, _, _, _ in targets.joints] + [k.joint for k in keepaways if k.joint is not None]
    table, cols, feet = _joint_columns(library, tracks, tracked, obstacles)
    joint_targets = tuple(
        JointTarget(n, t, j, cols.index(j), p, v, wt) for n, t, j, p, v, wt in targets.joints
    )
    keep = tuple(replace(k, column=-1 if k.joint is None else cols.index(k.joint)) for k in keepaways)
    grid = None
    if len(bodies) >= 2 or joint_targets or obstacles or keep:
        grid = fit_grid(
            length,
            [(b.frame, b.xz, b.heading, b.weight) for b in bodies],
            [jt.frame for jt in joint_targets],
            _obstacle_step(length) if obstacles or keep else None,
        )
    return Problem(
        length,
        fps,
        weights,
        tuple(bodies),
        joint_targets,
        tuple(poses),
        tuple(targets.labels),
        tuple(obstacles),
        keep,
        table,
        feet,
        grid,
    )


JointSpec = tuple[str, int, int, FloatArray, FloatArray | None, float]
"""A joint constraint before its column is known: name, output frame, joint, position, velocity, weight."""


class _Targets:
    """The request's constraints checked against the database, one target list per kind, named
    ``kind[i]`` in request order."""

    def __init__(self, library: MotionLibrary, tracks: RootTracks, length: int) -> None:
        self.library, self.tracks, self.length = library, tracks, length
        self.skeleton = library.motions[0].skeleton
        self.bodies: list[BodyTarget] = []
        self.joints: list[JointSpec] = []
        self.poses: list[PoseTarget] = []
        self.labels: list[LabelTarget] = []
        self.obstacles: list[ObstacleTarget] = []
        self._count: dict[str, int] = {}

    def add(self, c: Any) -> None:
        """Check and add one constraint of the request."""
        if c.type == "body":
            heading = None if c.heading_deg is None else float(np.radians(c.heading_deg))
            self.bodies.append(
                BodyTarget(
                    self.name("body"), self.timed(c, "body"), np.asarray(c.position, float), heading, c.weight
                )
            )
        elif c.type == "joint":
            self.joints.append(self.joint(c))
        elif c.type == "pose":
            self.poses.append(self.pose(c))
        elif c.type == "label":
            self.labels.append(self.label(c))
        elif c.type == "obstacle":
            region = (
                FloorRegion.disc(c.disc.center, c.disc.radius)
                if c.disc is not None
                else FloorRegion.from_polygon(c.polygon)
            )
            self.obstacles.append(ObstacleTarget(self.name("obstacle"), c.weight, region))
        else:  # pragma: no cover - the schema's union is closed
            raise EngineError(f"unknown constraint type {c.type!r}")

    def name(self, kind: str) -> str:
        i = self._count.get(kind, 0)
        self._count[kind] = i + 1
        return f"{kind}[{i}]"

    def timed(self, c: Any, kind: str) -> int:
        """The constraint's output frame (``frame`` or ``time_s``), inside the motion."""
        t = _frame_of(c, self.library.fps)
        if not 0 <= t < self.length:
            raise EngineError(
                f"{kind} constraint at output frame {t} is outside the motion (0..{self.length - 1})"
            )
        return t

    def joint(self, c: Any) -> JointSpec:
        try:
            j = self.skeleton.index(c.joint)
        except MotionError:
            raise EngineError(
                f"no joint named {c.joint!r}; joints: {', '.join(self.skeleton.names)}"
            ) from None
        vel = None if c.velocity is None else np.asarray(c.velocity, float)
        return self.name("joint"), self.timed(c, "joint"), j, np.asarray(c.position, float), vel, c.weight

    def pose(self, c: Any) -> PoseTarget:
        try:
            clip = self.library.index(c.clip)
        except MotionError as exc:
            raise EngineError(str(exc)) from None
        n = self.library.motions[clip].num_frames
        if c.clip_frame >= n:
            raise EngineError(
                f"pose constraint: clip {c.clip!r} has {n} frames, asked for frame {c.clip_frame}"
            )
        return PoseTarget(self.name("pose"), self.timed(c, "pose"), clip, int(c.clip_frame))

    def label(self, c: Any) -> LabelTarget:
        """A label range, with the cumulative count of the database frames that satisfy it."""
        start, end = min(int(c.start), self.length), min(int(c.end), self.length)
        if end <= start:
            raise EngineError(
                f"label constraint [{c.start}, {c.end}) is outside the motion (0..{self.length - 1})"
            )
        lab = _label_values(self.library, self.tracks, c.label)
        if c.value == 1 and not np.any(lab == 1):
            raise EngineError(f"no clip of the database carries the label {c.label!r}")
        good = (lab == 1) if c.value == 1 else (lab != 1)
        cum = np.zeros(int(self.tracks.offsets[-1]) + 1, dtype=np.int64)
        np.cumsum(good, out=cum[1:])
        return LabelTarget(self.name("label"), c.label, start, end, int(c.value), c.weight, cum)


def _joint_columns(
    library: MotionLibrary, tracks: RootTracks, joints: list[int], obstacles: list[ObstacleTarget]
) -> tuple[JointTable | None, list[int], IntArray]:
    """The joints whose positions the search tracks (the constrained ones, and the feet when there
    are obstacles): their table, the joint of each column, and the feet's columns."""
    feet = np.zeros(0, np.int64)
    cols: list[int] = sorted(set(joints))
    if obstacles:
        try:
            foot = [int(f) for f in foot_joints(library.motions[0].skeleton)]
        except MotionError:
            foot = []
        cols = sorted(set(cols) | set(foot))
        feet = np.array([cols.index(f) for f in foot], dtype=np.int64)
    return (JointTable(library, tracks, cols) if cols else None), cols, feet


def _obstacle_step(length: int) -> int:
    """Output frames between obstacle samples (2 or more, at most :data:`OBSTACLE_SAMPLES`)."""
    return max(2, -(-length // OBSTACLE_SAMPLES))


def _label_values(library: MotionLibrary, tracks: RootTracks, label: str) -> IntArray:
    """``(N,)`` per library frame: 1 labelled, -1 labelled "not", 0 unknown (clip label ranges
    are in database frames; later ranges override earlier ones)."""
    out = np.zeros(int(tracks.offsets[-1]), dtype=np.int64)
    for c, ranges in enumerate(library.labels):
        lo, n = int(tracks.offsets[c]), int(tracks.offsets[c + 1] - tracks.offsets[c])
        for r in ranges:
            if r.get("label") != label:
                continue
            s, e = max(int(r.get("start", 0)), 0), min(int(r.get("end", n)), n)
            if e > s:
                out[lo + s : lo + e] = int(r.get("value", 1))
    return out


# -- scoring -----------------------------------------------------------------------------------


@dataclass(slots=True)
class BatchScore:
    """Scores of a batch: ``total (B,)`` (inf when invalid), weighted ``terms`` by name, the batch
    with its start frames re-anchored (pose constraints), its pieces and placements
    (``theta (B, M + 1)``, ``shift (B, M + 1, 2)``, already anchored by the first body constraint)."""

    total: FloatArray
    terms: dict[str, FloatArray]
    valid: BoolArray
    batch: PathBatch
    pieces: BatchPieces
    theta: FloatArray
    shift: FloatArray


def anchor_poses(index: GraphIndex, problem: Problem, batch: PathBatch) -> tuple[PathBatch, BoolArray]:
    """Move each path's start frame so that the first pose constraint's clip frame plays at its
    time; ``ok (B,)`` is false where no occurrence of that frame can be so placed."""
    if not problem.poses:
        return batch, np.ones(batch.size, dtype=bool)
    pose = problem.poses[0]
    pieces = batch_pieces(index, batch, 1 << 40)
    live = pieces.count > 0
    holds = (
        live
        & (pieces.clip == pose.clip)
        & (pieces.first <= pose.clip_frame)
        & (pieces.last >= pose.clip_frame)
    )
    len0 = pieces.count[:, 0]
    last0 = pieces.last[:, 0]
    # time of the pose frame after piece 0, for pieces j >= 1; piece 0 itself is handled apart
    rel = pieces.start - len0[:, None] + (pose.clip_frame - pieces.first)
    new_len0 = pose.frame - rel
    f0 = last0[:, None] + 1 - new_len0
    ok_j = holds & (new_len0 >= 1) & (f0 >= 0)
    ok_j[:, 0] = False
    # piece 0: any start frame <= the pose frame in the start clip works
    f00 = pose.clip_frame - pose.frame
    ok_0 = (batch.start_clip == pose.clip) & (last0 >= pose.clip_frame) & (f00 >= 0)
    f0[:, 0] = f00
    ok_j[:, 0] = ok_0
    ok = ok_j.any(axis=1)
    pick = np.argmax(ok_j, axis=1)
    start = np.where(ok, f0[np.arange(batch.size), pick], batch.start_frame)
    # a path whose start already puts the pose frame at its time keeps it (several occurrences)
    _, clip, frame = locate(batch_pieces(index, batch, pose.frame + 1), pose.frame)
    holds_now = (clip == pose.clip) & (frame == pose.clip_frame) & (pieces.total > pose.frame)
    start = np.where(holds_now, batch.start_frame, start)
    return PathBatch(batch.start_clip, start.astype(np.int64), batch.edges), ok | holds_now


def _anchor_bodies(
    index: GraphIndex, problem: Problem, pieces: BatchPieces, theta: FloatArray, shift: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Turn and shift every path so the first body constraint is met (see the module docstring)."""
    b0 = problem.placed_by
    if b0 is None:
        return theta, shift
    yaw0, p0 = body_at(index, pieces, theta, shift, b0.frame)
    if b0.heading is not None:
        alpha = b0.heading - yaw0
    elif len(problem.bodies) > 1:
        b1 = problem.bodies[1]
        _, p1 = body_at(index, pieces, theta, shift, b1.frame)
        v = p1 - p0
        u = b1.xz - b0.xz
        alpha = np.where(
            np.linalg.norm(v, axis=-1) > 1e-6,
            np.arctan2(u[0], u[1]) - np.arctan2(v[:, 0], v[:, 1]),
            0.0,
        )
    else:
        alpha = np.zeros(yaw0.shape)
    t_a = b0.xz - rotate_floor(alpha, p0)
    th, sh = compose2(alpha[:, None], t_a[:, None, :], theta, shift)
    return th, sh


def body_at(
    index: GraphIndex, pieces: BatchPieces, theta: FloatArray, shift: FloatArray, t: int
) -> tuple[FloatArray, FloatArray]:
    """Root heading ``(B,)`` radians and floor position ``(B, 2)`` at output frame ``t``."""
    j, clip, frame = locate(pieces, t)
    rows = np.arange(j.size)
    yaw, xz = index.ground(clip, frame)
    th = theta[rows, j]
    return th + yaw, rotate_floor(th, xz) + shift[rows, j]


def _neutralise(batch: PathBatch, valid: BoolArray) -> PathBatch:
    """The batch with invalid rows replaced by a harmless path (clip 0 from frame 0, no edge), so
    that every index computed from it stays in range."""
    if valid.all():
        return batch
    bad = ~valid
    return PathBatch(
        np.where(bad, 0, batch.start_clip),
        np.where(bad, 0, batch.start_frame),
        np.where(bad[:, None], -1, batch.edges),
    )


def score_batch(index: GraphIndex, problem: Problem, batch: PathBatch, *, rough: bool = False) -> BatchScore:
    """Score every path of a batch (invalid paths and paths breaking a pose constraint score inf).

    ``rough``: a quicker estimate for ranking many candidates (chain seeds): body and joint
    errors as they are before assembly's correction (the paper's terms), obstacles left out."""
    valid = batch_valid(index, batch)
    batch = _neutralise(batch, valid)
    if problem.poses:
        batch, ok = anchor_poses(index, problem, batch)
        valid &= ok & batch_valid(index, batch)
        batch = _neutralise(batch, valid)
    T = problem.length
    pieces = batch_pieces(index, batch, T)
    for pose in problem.poses:
        _, c, f = locate(pieces, pose.frame)
        valid &= (c == pose.clip) & (f == pose.clip_frame) & (pieces.total > pose.frame)
    theta, shift = batch_transforms(index, batch)
    theta, shift = _anchor_bodies(index, problem, pieces, theta, shift)
    w = problem.weights
    rows = np.arange(batch.size)
    # continuity: edges whose next piece starts inside the output
    e = batch.edges
    cut = (e >= 0) & (pieces.start[:, 1:] < T)
    continuity = np.where(cut, index.tree.costs(np.maximum(e, 0)), 0.0).sum(axis=1)
    continuity += _short_pieces(pieces, T, problem.fps)
    length = (np.maximum(T - pieces.total, 0) / FRAMES_UNIT) ** 2
    fit = None if rough else _fit(index, problem, pieces, theta, shift)
    body = np.zeros(batch.size)
    joint = np.zeros(batch.size)
    if fit is not None and problem.grid is not None:
        grid = problem.grid
        for h in range(1, grid.head_at.size):
            inc = (fit.head_inc[:, h] / RADIANS_UNIT) ** 2 + (fit.head_excess[:, h] / EXCESS_RADIANS) ** 2
            body += grid.head_weight[h] * inc
        for gi in range(1, grid.floor_at.size):
            ref = int(grid.floor_ref[gi])
            wt = problem.bodies[ref].weight if grid.floor_kind[gi] == 0 else problem.joints[ref].weight
            inc, excess = fit.floor_inc[:, gi], fit.floor_excess[:, gi]
            cost = wt * ((inc / METRES_UNIT) ** 2 + (excess / EXCESS_METRES) ** 2)
            if grid.floor_kind[gi] == 0:
                body += cost
            else:
                joint += cost
    else:
        for b in problem.bodies[1:]:
            yaw, xz = body_at(index, pieces, theta, shift, b.frame)
            cost = (np.linalg.norm(xz - b.xz, axis=-1) / METRES_UNIT) ** 2
            if b.heading is not None:
                cost = cost + (wrap_angle(yaw - b.heading) / RADIANS_UNIT) ** 2
            body += b.weight * cost
    if problem.joints:
        assert problem.table is not None
        for jt in problem.joints:
            j, clip, frame = locate(pieces, jt.frame)
            p = problem.table.at(clip, frame)[:, jt.column]
            th = theta[rows, j]
            if fit is None:  # rough: the whole error as played
                xz = rotate_floor(th, p[:, [0, 2]]) + shift[rows, j]
                cost = ((xz - jt.position[[0, 2]]) ** 2).sum(-1) / METRES_UNIT**2
            else:  # the floor part is corrected by assembly (charged above as the correction it needs)
                cost = np.zeros(batch.size)
            cost = cost + (p[:, 1] - jt.position[1]) ** 2 / METRES_UNIT**2
            if jt.velocity is not None:
                v = problem.table.velocity(clip, frame, problem.fps)[:, jt.column]
                vxz = rotate_floor(th, v[:, [0, 2]])
                dv2 = ((vxz - jt.velocity[[0, 2]]) ** 2).sum(-1) + (v[:, 1] - jt.velocity[1]) ** 2
                cost = cost + dv2 / VELOCITY_UNIT**2
            joint += jt.weight * cost
    label = np.zeros(batch.size)
    for lb in problem.labels:
        lo = np.maximum(pieces.start, lb.start)
        hi = np.minimum(pieces.start + pieces.count, lb.end)
        span = np.maximum(hi - lo, 0)
        g = index.tracks.offsets[pieces.clip] + pieces.first + (lo - pieces.start)
        g = np.clip(g, 0, lb.good.size - 1)
        good = np.where(span > 0, lb.good[np.clip(g + span, 0, lb.good.size - 1)] - lb.good[g], 0).sum(axis=1)
        label += lb.weight * ((lb.end - lb.start) - good) / FRAMES_UNIT
    obstacle = _obstacles(problem, fit) if problem.obstacles and fit is not None else np.zeros(batch.size)
    shared = _keepaways(problem, fit) if problem.keepaways and fit is not None else np.zeros(batch.size)
    terms = {
        "continuity": w["continuity"] * continuity,
        "length": w["length"] * length,
        "body": w["body"] * body,
        "joint": w["joint"] * joint,
        "label": w["label"] * label,
        "obstacle": w["obstacle"] * obstacle,
        "shared": w["shared"] * shared,
    }
    total = sum(terms.values(), np.zeros(batch.size))
    total = np.where(valid, total, np.inf)
    return BatchScore(total, terms, valid, batch, pieces, theta, shift)


def _short_pieces(pieces: BatchPieces, length: int, fps: float) -> FloatArray:
    """``(B,)`` the penalty of pieces shorter than :data:`MIN_PIECE_S` between two cuts (not the
    first or the last piece): ``SHORT_PIECE_COST * (missing frames / shortest)^2`` each."""
    shortest = max(2, int(round(MIN_PIECE_S * fps)))
    count = pieces.count
    inner = (count > 0) & (pieces.start > 0) & (pieces.start + count < length)
    missing = np.where(inner, np.maximum(shortest - count, 0), 0) / shortest
    return np.asarray(SHORT_PIECE_COST * (missing**2).sum(axis=1))


def _fit(
    index: GraphIndex, problem: Problem, pieces: BatchPieces, theta: FloatArray, shift: FloatArray
) -> BatchFit | None:
    """The estimated body-constraint correction of the batch (:mod:`engines.graph.fit`), or
    ``None`` when the problem has no goal to correct towards nor obstacle to test."""
    if problem.grid is None:
        return None
    body_xz = np.array([b.xz for b in problem.bodies], dtype=np.float64).reshape(-1, 2)
    joint_xz = np.array([j.position[[0, 2]] for j in problem.joints], dtype=np.float64).reshape(-1, 2)
    columns = np.array([j.column for j in problem.joints], dtype=np.int64)
    return batch_fit(
        index,
        problem.grid,
        pieces,
        theta,
        shift,
        body_xz,
        joint_xz,
        problem.table,
        columns,
        problem.fps,
        with_goal=bool(problem.obstacles or problem.keepaways),
    )


def _obstacles(problem: Problem, fit: BatchFit) -> FloatArray:
    """Obstacle term ``(B,)`` (unweighted by ``w_o``) at the corrected sample frames."""
    assert problem.grid is not None
    grid = problem.grid
    step = grid.step
    cols = grid.samples
    root = fit.goal[:, cols][:, :, None, :]  # (B, S, 1, 2)
    pts = [root]
    if problem.foot_columns.size and problem.table is not None:
        feet = problem.table.at(fit.clip[:, cols], fit.frame[:, cols])[..., problem.foot_columns, :]
        pts.append(fit.corrected(feet[..., [0, 2]], cols))
    world = np.concatenate(pts, axis=-2)  # (B, S, K, 2)
    out = np.zeros(world.shape[0])
    for ob in problem.obstacles:
        d = ob.depth(world, OBSTACLE_MARGIN).max(axis=-1)  # (B, S)
        out += ob.weight * np.where(
            d > 0, (step / FRAMES_UNIT) * (1.0 + d / OBSTACLE_DEPTH_UNIT) ** 2, 0.0
        ).sum(axis=1)
    return out


def _keepaways(problem: Problem, fit: BatchFit) -> FloatArray:
    """Keep-away term ``(B,)`` (unweighted by ``w_h``): at the corrected sample frames inside each
    target's range, the body (or joint) closer to the other's floor point than ``radius`` plus
    :data:`OBSTACLE_MARGIN` costs like an obstacle sample that deep."""
    assert problem.grid is not None
    grid = problem.grid
    step = grid.step
    cols = grid.samples
    frames = grid.frames[cols]
    out = np.zeros(fit.goal.shape[0])
    for k in problem.keepaways:
        inside = (frames >= k.start) & (frames < k.end)
        if not inside.any():
            continue
        c = cols[inside]
        if k.column < 0 or problem.table is None:
            pts = fit.goal[:, c]  # (B, S, 2)
        else:
            local = problem.table.at(fit.clip[:, c], fit.frame[:, c])[..., [k.column], :][..., [0, 2]]
            pts = fit.corrected(local, c)[:, :, 0]
        gap = np.linalg.norm(pts - k.track[frames[inside]][None], axis=-1)
        d = np.maximum(k.radius + OBSTACLE_MARGIN - gap, 0.0)
        cost = np.where(d > 0, (step / FRAMES_UNIT) * (1.0 + d / OBSTACLE_DEPTH_UNIT) ** 2, 0.0)
        out += k.weight * cost.sum(axis=1)
    return out


@dataclass(frozen=True, slots=True)
class Evaluation:
    """One scored path with what assembly needs: its (anchored) path, pieces and placement."""

    path: Path
    score: float
    terms: dict[str, float]
    pieces: Pieces
    placement: Placement


def evaluate(index: GraphIndex, problem: Problem, path: Path) -> Evaluation:
    """Score one path and place its pieces."""
    s = score_batch(index, problem, PathBatch.from_paths([path]))
    anchored = s.batch.path(0)
    pieces = path_pieces(index, anchored, problem.length)
    n = pieces.clip.size
    placement = Placement(s.theta[0, :n].copy(), s.shift[0, :n].copy(), pieces, index.tracks)
    return Evaluation(
        anchored, float(s.total[0]), {k: float(v[0]) for k, v in s.terms.items()}, pieces, placement
    )
