"""Several characters whose constraints refer to each other (Arikan & Forsyth 2002, Sec. 5, fig. 9).

A request with ``characters`` (each with its own constraints) and ``shared`` constraints naming
two of them (:class:`schemas.graph.MeetConstraint`: "character 0's right hand meets character 1's
left hand at frame 150", or two bodies passing at a distance; :class:`schemas.graph.ApartConstraint`:
"they stay at least 0.5 m apart") is searched by **coordinate descent over the characters**
(block Gauss-Seidel), the coupling the paper describes for its two interacting characters: each
character in turn is searched by the ordinary :class:`~engines.graph.search.GraphSearch` with the
shared constraints turned into its own constraints against the *other* character's current
motion, which is held fixed:

* a **meet** becomes, for the searched character, a joint constraint (its joint at the other's
  joint position at that frame, offset by ``distance_m`` on the floor towards where it already
  is) or a body constraint (for a body), so assembly's floor correction
  (:mod:`engines.graph.fit`, :func:`motion.floorfit.floor_correction`) moves it there within the
  database's physical limits, exactly as for a constraint the request set;
* an **apart** becomes a moving keep-out disc (:class:`~engines.graph.score.KeepawayTarget`): the
  other's floor point at each output frame, of radius ``min_m``, scored at the corrected sample
  frames like an obstacle. For joints the search keeps their *floor* distance above the minimum,
  which bounds the 3-D distance the report measures from below.

Pass 0 searches character 0 alone, then each next one against those already found; every later
pass (``coupling_rounds``) searches each character again, warm-started from its current path
(:meth:`GraphSearch.run`'s ``warm``: the search returns nothing its current path beats under
the new targets). The pair's score is the sum of each character's own score (its request's
constraints, :func:`engines.graph.score.evaluate`) and the shared constraints' costs measured on
the assembled motions in the same units (:func:`shared_cost`); a new combination is emitted only
when that score improves, and the passes stop when a pass does not improve it. Every search is
bounded by work, as a single character's is (its ``rounds`` or convergence, each with its own seed
derived from the request's, character and pass): the passes never split a time budget, so the
same request and seed give the same motions at any load. ``budget_s`` is one safety cap over the
whole request (a :class:`~engines.base.Run` shared by every search): when it cuts a search short,
the characters found so far are combined and the search returns ``Stopped.budget``.

Why not one joint search over pairs of paths: the graph search scores batches of paths of one
character against fixed targets (vectorised over thousands of candidates); a pair search would
score the product of two candidate sets, and every shared term couples the two corrections.
Coordinate descent keeps every existing tool (seeds, mutations, the correction estimate) and,
measured on the bundled CMU walks (``bench/graph_shared.py``: a high five and a pass, 4 seeds
each, 10 s per request on a loaded 2-core machine), the later passes matter: with pass 0 alone
(``coupling_rounds: 0``, the second walker placed against the first) the meets missed by 6.1 cm
on average (worst 20.7, 5 of 8 within 5 cm); with 3 rounds by 0.7 cm (worst 4.9, 8 of 8).

**Reach.** Assembly's correction moves bodies on the floor; the height of a hand at a frame (the
phase of an arm swing) only follows from the clips chosen. So when the passes are done, each
joint-to-joint meet still open by at most :data:`REACH_MAX_M` is closed by arm IK
(:func:`motion.reach.reach_at`): each of the two joints goes half the way, faded in and out over
:data:`REACH_S`; the quality report (plausibility included) is measured after it.

Output: one motion on the combined skeleton of :mod:`engines.combine` (joints ``c0_...``,
``c1_...`` under a static ``world`` root), with a quality report holding every character's own
goals (named ``c0.body[1]``...) and every shared one (``shared[0]``: distance at the frame,
smallest separation and where, :mod:`motion.goals`), all measured on that output.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from motion import Motion, MotionError
from motion.goals import (
    ApartGoal,
    BodyGoal,
    Character,
    Goal,
    JointGoal,
    LabelGoal,
    LengthGoal,
    MeetGoal,
    ObstacleGoal,
    PathGoal,
    Point,
    PoseGoal,
    point_distance,
)
from motion.ground import body_root
from motion.plausibility import Reference
from motion.quality import QualityInputs
from motion.reach import reach_at
from schemas.graph import GraphRequest

from ..base import (
    CollectingEmitter,
    Emitter,
    EngineError,
    Run,
    ShouldStop,
    Solution,
    Stopped,
    finish_solution,
)
from ..combine import combine_motions, combined_characters
from ..library import MotionLibrary
from .assemble import quality_inputs
from .model import EdgeTree, FootContacts, RootTracks
from .paths import GraphIndex, Path
from .score import (
    EXCESS_METRES,
    FRAMES_UNIT,
    METRES_UNIT,
    OBSTACLE_DEPTH_UNIT,
    KeepawayTarget,
    compile_problem,
    evaluate,
)
from .search import GraphSearch

Array = np.ndarray[Any, np.dtype[np.float64]]

MEET_WEIGHT = 40.0
"""Weight of the constraint a meet becomes for the searched character, times the request's: the
floor part of a meet is corrected by assembly, but its height part (two hands at one height, an
arm-swing phase) only by choosing the path, and at weight 1 a 10 cm height error costs a tenth
of a transition. On the bundled walks (``bench/graph_shared.py``, high five, 3 seeds, 8 s) the
hands met within 13.3 cm on average (worst 21.5) at weight 1, and 7.1 (worst 7.6) at 40."""


@dataclass(slots=True)
class _State:
    """One character's current result: its path, assembled motion (metres), joint positions
    ``(F, J, 3)`` metres, own score and the solution the search emitted."""

    path: Path
    motion: Motion
    positions: Array
    own: float
    solution: Solution


def shared_cost(
    goal: MeetGoal | ApartGoal, weight: float, positions: Array, characters: Sequence[Character]
) -> float:
    """A shared constraint's cost on an output (``positions (F, J, 3)`` metres) in the score's
    units (:mod:`engines.graph.score`): a meet ``weight * ((error / 0.30 m)^2 + (excess over the
    tolerance / 5 cm)^2)``; an apart, per frame closer than the minimum by ``d`` metres,
    ``weight * (1 / 10) * (1 + d / 5 cm)^2``."""
    if isinstance(goal, MeetGoal):
        if goal.frame >= positions.shape[0]:  # a short output misses the meet: cost it as 1 m off
            return weight * (
                (1.0 / METRES_UNIT) ** 2 + (max(1.0 - goal.tolerance_cm / 100, 0.0) / EXCESS_METRES) ** 2
            )
        at = float(point_distance(goal.a, goal.b, positions[goal.frame : goal.frame + 1], characters)[0])
        err = abs(at - goal.distance_m)
        excess = max(err - goal.tolerance_cm / 100, 0.0)
        return weight * ((err / METRES_UNIT) ** 2 + (excess / EXCESS_METRES) ** 2)
    end = positions.shape[0] if goal.end is None else min(goal.end, positions.shape[0])
    d = point_distance(goal.a, goal.b, positions[goal.start : end], characters)
    depth = np.maximum(goal.min_m - d, 0.0)
    return weight * float(
        np.where(depth > 0, (1.0 / FRAMES_UNIT) * (1.0 + depth / OBSTACLE_DEPTH_UNIT) ** 2, 0.0).sum()
    )


class CoupledSearch:
    """Coordinate descent over several characters' graph searches (module docstring)."""

    def __init__(
        self,
        library: MotionLibrary,
        tree: EdgeTree,
        tracks: RootTracks,
        seed: int = 0,
        *,
        contacts: FootContacts | None = None,
        reference: Reference | None = None,
        foot_floor: dict[int, tuple[float, float]] | None = None,
    ) -> None:
        self.library = library
        self.tree = tree
        self.tracks = tracks
        self.seed = seed
        self.contacts = contacts
        self.reference = reference
        self.foot_floor = foot_floor
        self.skeleton = library.motions[0].skeleton
        self.index_ = GraphIndex.of(tree, tracks)
        self.passes_ = 0

    # -- the request ---------------------------------------------------------------------------
    def _joint(self, name: str | None, where: str) -> int | None:
        if name is None:
            return None
        try:
            return int(self.skeleton.index(name))
        except MotionError:
            raise EngineError(
                f"{where}: no joint named {name!r}; joints: {', '.join(self.skeleton.names)}"
            ) from None

    def _frame(self, c: Any, length: int, where: str) -> int:
        t = int(c.frame) if c.frame is not None else round(float(c.time_s) * self.library.fps)
        if not 0 <= t < length:
            raise EngineError(f"{where}: output frame {t} is outside the motion (0..{length - 1})")
        return t

    def shared_goals(self, request: GraphRequest, length: int) -> list[tuple[MeetGoal | ApartGoal, float]]:
        """The request's shared constraints as goals on the combined output (joint indices of the
        combined skeleton: ``1 + character * J + joint``), each with its weight."""
        nj = self.skeleton.num_joints
        out: list[tuple[MeetGoal | ApartGoal, float]] = []
        for i, c in enumerate(request.shared):
            where = f"shared[{i}] ({c.type})"
            pts = []
            for p in (c.a, c.b):
                j = self._joint(p.joint, where)
                label = f"c{p.character}.{p.joint or 'body'}"
                pts.append(Point(p.character, None if j is None else 1 + p.character * nj + j, label))
            wt = float(c.weight) * float(request.weights.shared)
            if c.type == "meet":
                goal: MeetGoal | ApartGoal = MeetGoal(
                    f"shared[{i}]",
                    self._frame(c, length, where),
                    pts[0],
                    pts[1],
                    float(c.distance_m),
                    float(c.tolerance_cm),
                )
            else:
                end = length if c.end is None else int(c.end)
                if not 0 <= int(c.start) < end <= length:
                    raise EngineError(
                        f"{where}: frames [{c.start}, {end}) are outside the motion (0..{length})"
                    )
                goal = ApartGoal(f"shared[{i}]", pts[0], pts[1], float(c.min_m), int(c.start), end)
            out.append((goal, wt))
        return out

    def _derived(
        self,
        request: GraphRequest,
        i: int,
        shared: list[tuple[MeetGoal | ApartGoal, float]],
        states: list[_State | None],
        length: int,
    ) -> tuple[Any, tuple[KeepawayTarget, ...]]:
        """Character ``i``'s request with the shared constraints turned into its own constraints
        against the others' current motions (module docstring), and its keep-away targets."""
        from schemas.graph import BodyConstraint, JointConstraint

        nj = self.skeleton.num_joints
        own = list((request.characters or [])[i].constraints)
        keep: list[KeepawayTarget] = []
        me = states[i]
        for goal, wt in shared:
            if goal.a.character == i:
                mine, other = goal.a, goal.b
            elif goal.b.character == i:
                mine, other = goal.b, goal.a
            else:
                continue
            st = states[other.character]
            if st is None:
                continue
            q = self._point(other, st.positions, nj)  # (F, 3) metres, in the other's own motion
            if q.shape[0] < length:  # a short motion (out of time) stands at its last frame
                q = np.concatenate((q, np.repeat(q[-1:], length - q.shape[0], axis=0)))
            my_joint = None if mine.joint is None else mine.joint - 1 - i * nj
            if isinstance(goal, MeetGoal):
                t = goal.frame
                target = q[t].copy()
                if goal.distance_m > 0:
                    here = (
                        None
                        if me is None
                        else self._point(mine, me.positions, nj)[min(t, me.positions.shape[0] - 1)]
                    )
                    target = target + goal.distance_m * _beside(q, t, here, self.library.fps)
                wm = min(wt * MEET_WEIGHT, 1000.0)
                if my_joint is None:
                    own.append(
                        BodyConstraint(frame=t, position=(float(target[0]), float(target[2])), weight=wm)
                    )
                else:
                    if other.joint is None:  # floor distance: the joint keeps its own height
                        ref = me.positions if me is not None else self._rest_positions()
                        target[1] = float(ref[min(t, ref.shape[0] - 1), my_joint, 1])
                    own.append(
                        JointConstraint(
                            frame=t,
                            joint=self.skeleton.names[my_joint],
                            position=(float(target[0]), float(target[1]), float(target[2])),
                            weight=wm,
                        )
                    )
            else:
                keep.append(
                    KeepawayTarget(
                        goal.name,
                        wt,
                        my_joint,
                        np.ascontiguousarray(q[:, [0, 2]]),
                        goal.min_m,
                        goal.start,
                        goal.end or length,
                    )
                )
        sub = request.model_copy(
            update={"characters": None, "shared": [], "constraints": own, "alternatives": 1}
        )
        return sub, tuple(keep)

    def _rest_positions(self) -> Array:
        m = self.library.motions[0]
        return np.asarray(m.global_positions() * m.metres_per_unit, dtype=np.float64)

    def _point(self, p: Point, positions: Array, nj: int) -> Array:
        """``(F, 3)`` metres of a shared point in its character's own motion (body: on the floor)."""
        if p.joint is not None:
            return np.asarray(positions[:, p.joint - 1 - p.character * nj], dtype=np.float64)
        hips = positions[:, body_root(self.skeleton)]
        return np.stack((hips[:, 0], np.zeros(hips.shape[0]), hips[:, 2]), axis=-1)

    # -- the search ----------------------------------------------------------------------------
    def run(self, request: GraphRequest, budget_s: float, emit: Emitter, should_stop: ShouldStop) -> Stopped:
        """Search the characters jointly until the passes converge or ``coupling_rounds`` passes
        are done, emitting every better combination (module docstring); ``budget_s`` and
        ``should_stop()`` only cut it short. Returns why it stopped."""
        run = Run(budget_s, should_stop)
        n = len(request.characters or [])
        base = [
            request.model_copy(
                update={
                    "characters": None,
                    "shared": [],
                    "constraints": list(c.constraints),
                    "alternatives": 1,
                }
            )
            for c in request.characters or []
        ]
        owns = [compile_problem(b, self.library, self.tracks) for b in base]
        length = owns[0].length
        shared = self.shared_goals(request, length)
        states: list[_State | None] = [None] * n
        passes = 1 + int(request.coupling_rounds)
        best_score = np.inf
        for p in range(passes):
            improved = False
            for i in range(n):
                # past the time cap only a character without a motion yet is searched (its first
                # seeds are drawn whatever the clock): a request cut short still answers
                if run.cancelled() or (states[i] is not None and run.over()):
                    continue
                sub, keep = self._derived(request, i, shared, states, length)
                search = GraphSearch(
                    self.library,
                    self.tree,
                    self.tracks,
                    (int(request.seed) + 7919 * i + 104729 * p) % 2**32,
                    contacts=self.contacts,
                    reference=self.reference,
                    foot_floor=self.foot_floor,
                )
                collect = CollectingEmitter()
                old = states[i]
                search.run(
                    sub,
                    budget_s,
                    collect,
                    should_stop,
                    keepaways=keep,
                    warm=None if old is None else old.path,
                    cap=run,
                )
                got = collect.latest
                if got is None or search.best_path_ is None:
                    continue
                if old is not None and got.motion.num_frames < old.motion.num_frames:
                    continue  # cut short with a shorter path: keep the full one
                m = got.motion
                pos = np.asarray(m.global_positions() * m.metres_per_unit, dtype=np.float64)
                own = evaluate(self.index_, owns[i], search.best_path_).score
                states[i] = _State(search.best_path_, m, pos, own, got)
            if run.stopped is Stopped.cancelled:
                break
            self.passes_ = p + 1
            if all(s is not None for s in states):
                ready = [s for s in states if s is not None]
                solution = self._solution(request, ready, shared, owns)
                improved = solution.score < best_score - 1e-9
                if improved:
                    best_score = solution.score
                    emit.solution(solution)
            if run.stopped is not None or (p > 0 and not improved):
                break
        return run.outcome()

    def _solution(
        self,
        request: GraphRequest,
        states: list[_State],
        shared: list[tuple[MeetGoal | ApartGoal, float]],
        owns: list[Any],
    ) -> Solution:
        """The combined solution of the characters' current motions and its quality report."""
        # a character whose search ran out of time with a short path shortens the whole output (the
        # report's length goal says so)
        frames = min(s.motion.num_frames for s in states)
        motions = self._reach([s.motion.slice(0, frames) for s in states], shared)
        prefixes = [f"c{i}_" for i in range(len(states))]
        motion = combine_motions(motions, prefixes, "graph")
        chars = combined_characters([(f"c{i}", m.skeleton) for i, m in enumerate(motions)], motion)
        positions = np.asarray(motion.global_positions() * motion.metres_per_unit, dtype=np.float64)
        costs = [shared_cost(g, w, positions, chars) for g, w in shared]
        own = [s.own for s in states]
        goals: list[Goal] = [LengthGoal(owns[0].length)]
        for i, s in enumerate(states):
            goals += self._own_goals(i, s, owns[i], chars)
        goals += [g for g, _ in shared]
        terms: dict[str, float] = {}
        for s in states:
            for k, v in s.solution.terms.items():
                terms[k] = terms.get(k, 0.0) + float(v)
        terms["shared"] = float(sum(costs))
        solution = Solution(
            motion=motion,
            score=float(sum(own) + sum(costs)),
            terms=terms,
            provenance=list(states[0].solution.provenance),
            metrics={
                "characters": float(len(states)),
                "coupling_passes": float(self.passes_),
                **{f"c{i}_score": float(v) for i, v in enumerate(own)},
            },
            annotations={
                "characters": len(states),
                "provenance": [[list(p) for p in s.solution.provenance] for s in states],
            },
        )
        inputs = QualityInputs(goals=tuple(goals), characters=chars, joins=self._joins(states))
        return finish_solution(solution, inputs, self.reference)

    def _reach(self, motions: list[Motion], shared: list[tuple[MeetGoal | ApartGoal, float]]) -> list[Motion]:
        """The characters' motions with the hands of every joint-to-joint meet brought together by
        arm IK (:func:`motion.reach.reach_at`): each joint goes half of what is left, when that is
        within :data:`REACH_MAX_M`, faded over :data:`REACH_S` either side of the frame."""
        nj = self.skeleton.num_joints
        out = list(motions)
        window = max(1, round(REACH_S * self.library.fps))
        for goal, _ in shared:
            if not isinstance(goal, MeetGoal) or goal.a.joint is None or goal.b.joint is None:
                continue
            t = goal.frame
            if t >= out[0].num_frames:
                continue
            ends = [(p.character, int(p.joint or 0) - 1 - p.character * nj) for p in (goal.a, goal.b)]
            at = [out[c].slice(t, t + 1).global_positions()[0, j] * out[c].metres_per_unit for c, j in ends]
            gap = at[1] - at[0]
            d = float(np.linalg.norm(gap))
            move = (d - goal.distance_m) / 2
            if d < 1e-9 or abs(move) * 100 <= 0.1 or abs(move) > REACH_MAX_M:
                continue
            step = gap / d * move
            for (c, j), here, sign in zip(ends, at, (1.0, -1.0), strict=True):
                with contextlib.suppress(MotionError):  # no arm above the joint: the meet stays as it is
                    out[c], _ = reach_at(out[c], j, t, here + sign * step, window)
        return out

    def _joins(self, states: list[_State]) -> np.ndarray[Any, np.dtype[np.intp]]:
        """Every character's cut frames, as the report's joins."""
        return np.array(sorted({int(f) for s in states for f in _cuts(s.solution.provenance)}), dtype=np.intp)

    def _own_goals(self, i: int, s: _State, own: Any, chars: Sequence[Character]) -> list[Goal]:
        """Character ``i``'s own goals (its request's constraints, not the derived ones) on the
        combined output: names ``c{i}.body[1]``..., joints offset to the combined skeleton,
        bodies, poses and paths of character ``i``, obstacles tested on character ``i``."""
        prov = s.solution.provenance
        inputs = quality_inputs(s.motion, prov, _cuts(prov), own, self.library)
        base = int(chars[i].joints[0])
        out: list[Goal] = []
        for g in inputs.goals:
            if isinstance(g, LengthGoal):
                continue
            name = f"c{i}.{g.name}"
            if isinstance(g, BodyGoal | PoseGoal | PathGoal):
                out.append(replace(g, name=name, character=i))
            elif isinstance(g, JointGoal):
                out.append(replace(g, name=name, joint=base + g.joint))
            elif isinstance(g, ObstacleGoal):
                out.append(replace(g, name=name, characters=(i,)))
            elif isinstance(g, LabelGoal):
                out.append(replace(g, name=name))
            else:  # pragma: no cover - graph requests set no other goal
                raise EngineError(f"{g.name}: a goal the coupled search cannot place")
        return out


def _cuts(provenance: list[tuple[str, int]]) -> np.ndarray[Any, np.dtype[np.intp]]:
    """Output frames where the source jumps (another clip, or not the next frame)."""
    return np.array(
        [
            f
            for f in range(1, len(provenance))
            if provenance[f][0] != provenance[f - 1][0] or provenance[f][1] != provenance[f - 1][1] + 1
        ],
        dtype=np.intp,
    )


REACH_MAX_M = 0.3
"""Largest distance (metres) each of two meeting joints is moved by arm IK at the end."""
REACH_S = 0.4
"""Seconds over which that reach fades in before the meet and out after it."""

WALKING_M_S = 0.2
"""Speed (m/s) above which a meet at a distance puts the searched character beside the other."""


def _beside(q: Array, t: int, here: Array | None, fps: float) -> Array:
    """The floor direction ``(3,)`` (unit, ``y`` 0) from the other's point ``q[t]`` to where a meet
    at a distance puts the searched character: when the other moves (faster than
    :data:`WALKING_M_S`), square to its direction of travel (passing side by side) on the side
    the character already is (its left when unknown); standing, towards where the character is
    (+X when unknown)."""
    flat = np.array([1.0, 0.0, 1.0])
    a, b = max(t - 1, 0), min(t + 1, q.shape[0] - 1)
    v = (q[b] - q[a]) * flat
    speed = float(np.linalg.norm(v)) * fps / max(b - a, 1)
    rel = np.zeros(3) if here is None else (here - q[t]) * flat
    if speed > WALKING_M_S:
        u = v / np.linalg.norm(v)
        side = rel - float(rel @ u) * u
        if float(np.linalg.norm(side)) < 1e-6:
            side = np.array([u[2], 0.0, -u[0]])  # the mover's left (facing +Z, the left is +X)
        return np.asarray(side / np.linalg.norm(side))
    n = float(np.linalg.norm(rel))
    return np.asarray(rel / n) if n > 1e-6 else np.array([1.0, 0.0, 0.0])
