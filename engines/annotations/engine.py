"""The annotation engine as the runtime sees it (Arikan, Forsyth & O'Brien 2003).

Database kind ``annotated`` (:class:`schemas.annotations.AnnotatedDatabaseSpec`): ``build``
propagates the clips' labels by SVM and stores the continuity features and block clusterings
(:mod:`engines.annotations.build`). Request ``engine: "annotations"``
(:class:`schemas.annotations.AnnotationRequest`): ``search`` runs coarse-to-fine DP passes with new
random active sets (``passes`` of them: the search's work), emitting every better motion
(:mod:`engines.annotations.search`).

Example
-------
>>> from schemas.annotations import AnnotationRequest
>>> req = AnnotationRequest(frames=450, timeline=[{"label": "walk", "start": 0, "end": 200},
...     {"label": "run", "start": 200, "end": 450}], seed=3)
>>> engine = AnnotationEngine(library, arrays)  # doctest: +SKIP
>>> engine.search(req, Run(2.0))  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

from motion.floorfit import CorrectionLimits
from motion.looping import close_loop, with_loop_goal
from schemas import LabelRange
from schemas.annotations import AnnotatedDatabaseSpec, AnnotationRequest, ClipLabels, LabelCorrection
from schemas.bases import DatabaseSpecBase

from ..base import (
    Arrays,
    DatabaseArrays,
    DatabaseFacts,
    Emitter,
    Engine,
    EngineError,
    OutputEstimate,
    Run,
    ShouldStop,
    Solution,
    Stopped,
)
from ..library import MotionLibrary, clip_sources, with_mirrors
from .assemble import Frames, assemble, discontinuity, label_report, quality_inputs
from .build import BLAS_THREADS, build_annotated
from .corrections import apply_corrections, propagated_ranges
from .labels import LabelTable
from .search import (
    Candidate,
    Database,
    Problem,
    blocks_to_sigma,
    child_active,
    force_constraints,
    refine_boundaries,
    solve_level,
    spliced,
    top_active,
)


class AnnotationSearch:
    """One request's anytime search state (pools, random generator)."""

    def __init__(self, db: Database, request: AnnotationRequest) -> None:
        self.db = db
        self.request = request
        self.pb = Problem.compile(request, db)
        for level in db.levels:
            if level.clusters == 0:
                raise EngineError(
                    f"no clip is {level.size} frames long: rebuild the database with smaller block_sizes"
                )
        self.rng = np.random.default_rng(int(request.seed))
        self.pools: list[list[Candidate]] = [[] for _ in db.levels]

    def _level_result(self, level: int, starts: Any, size: int) -> tuple[Candidate, Any]:
        """The level's solution as a candidate; with an end constraint, the best single cut to or
        from the level's pool replaces it when better (Sec. 3.4), and the pool is updated."""
        db, pb = self.db, self.pb
        cand = Candidate.of(db, pb, blocks_to_sigma(starts, size, pb.n))
        if not pb.has_end:
            return cand, starts
        pool = self.pools[level]
        best: tuple[float, Any] = (cand.score, None)
        for y in pool:
            for first, second in ((cand, y), (y, cand)):
                score, k = spliced(db, pb, first, second, size)
                if score < best[0] - 1e-9:
                    best = (score, (first, second, k))
        current = cand
        if best[1] is not None:
            first, second, k = best[1]
            current = Candidate.of(db, pb, np.concatenate((first.sigma[:k], second.sigma[k:])))
        for c in {id(cand): cand, id(current): current}.values():
            if not any(np.array_equal(c.sigma, p.sigma) for p in pool):
                pool.append(c)
        pool.sort(key=lambda c: c.score)
        del pool[int(self.request.pool_size) :]
        return current, current.sigma[::size][: -(-pb.n // size)]

    def one_pass(self) -> Candidate:
        """One 32/16/8 pass from a fresh random active set, refined at the boundaries."""
        db, pb, req = self.db, self.pb, self.request
        top = db.levels[0]
        starts, _ = solve_level(db, pb, top_active(db, pb, self.rng), top.size)
        cand, starts = self._level_result(0, starts, top.size)
        size = top.size
        for i, level in enumerate(db.levels[1:], start=1):
            active = child_active(db, pb, starts, size, level, int(req.active_per_cluster), self.rng)
            starts, _ = solve_level(db, pb, active, level.size)
            size = level.size
            cand, starts = self._level_result(i, starts, size)
        sigma = force_constraints(db, pb, refine_boundaries(db, pb, cand.sigma, int(req.refine_frames)))
        return Candidate.of(db, pb, sigma)


class AnnotationEngine(Engine[AnnotationRequest, AnnotatedDatabaseSpec]):
    """Motion synthesis from annotations: SVM label propagation and coarse-to-fine DP."""

    name = "annotations"
    kind = "annotated"
    request_model = AnnotationRequest
    spec_model = AnnotatedDatabaseSpec

    def __init__(self, library: MotionLibrary, arrays: Arrays) -> None:
        super().__init__(library, arrays)
        self.db = Database.from_arrays(library, arrays)
        self.frames = Frames(library, arrays)

    @classmethod
    def build(
        cls, spec: AnnotatedDatabaseSpec, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop
    ) -> Arrays:
        return build_annotated(spec, library, emit, should_stop)

    @classmethod
    def library_for(cls, spec: AnnotatedDatabaseSpec, library: MotionLibrary) -> MotionLibrary:
        """With ``mirror``, the clips followed by their mirror images (labels' sides exchanged:
        :func:`engines.library.with_mirrors`)."""
        return with_mirrors(library) if spec.mirror else library

    @classmethod
    def clip_sources(cls, stored_spec: Mapping[str, Any], stored: int) -> list[int | None]:
        """The clips, then their mirror images with ``mirror``."""
        repeats = 2 if stored_spec.get("mirror") else 1
        return clip_sources(len(stored_spec.get("clips") or []), repeats, stored)

    @classmethod
    def library_frames(cls, spec: AnnotatedDatabaseSpec, frames: int) -> int:
        """Twice the clips' frames with ``mirror``."""
        return 2 * frames if spec.mirror else frames

    @classmethod
    def estimate(cls, request: AnnotationRequest, facts: DatabaseFacts) -> OutputEstimate:
        """``frames`` (database frames); 300 bytes per joint-frame."""
        return replace(
            super().estimate(request, facts), frames=int(request.frames), bytes_per_joint_frame=300
        )

    @classmethod
    def check_labels(cls, database_id: str) -> None:
        """Every annotated database carries labels."""

    @classmethod
    def clip_labels(
        cls, arrays: DatabaseArrays, clip: str, start: int = 0, end: int | None = None
    ) -> ClipLabels:
        """A clip's labels as ranges, from the database's label table alone
        (:class:`~engines.annotations.labels.LabelTable`)."""
        table = LabelTable.read(arrays)
        frames = int(table.counts[table.clip_index(clip)])
        ranges = [LabelRange(**r) for r in propagated_ranges(table, clip, start, end)]
        return ClipLabels(clip=clip, frames=frames, labels=ranges)

    @classmethod
    def corrected_spec(
        cls, spec: DatabaseSpecBase, corrections: Sequence[LabelCorrection], arrays: DatabaseArrays | None
    ) -> AnnotatedDatabaseSpec:
        """:func:`~engines.annotations.corrections.apply_corrections` with the database's label table."""
        if not isinstance(spec, AnnotatedDatabaseSpec):
            raise EngineError(f"a {spec.kind!r} spec carries no labels to correct")
        table = None if arrays is None else LabelTable.read(arrays)
        return apply_corrections(spec, list(corrections), table)

    def solution(
        self, cand: Candidate, pb: Problem, request: AnnotationRequest, passes: int, elapsed: float
    ) -> Solution:
        """The assembled motion and report of a candidate."""
        ref = self.quality_reference
        limits = CorrectionLimits(ref.root_speed_max, ref.turn_rate_max)
        floor = self.foot_floor(self.library.motions[0].skeleton)
        motion, cuts = assemble(
            self.db,
            self.frames,
            pb,
            cand,
            int(request.smoothing_frames),
            request.feet_mode() != "free",
            limits,
            floor,
            lock=request.feet_mode() == "lock",
        )
        if getattr(request, "loop", False):
            motion = close_loop(motion)
        annotations, metrics = label_report(self.db, pb, cand.sigma)
        metrics.update(discontinuity(motion, cuts))
        metrics.update({"passes": float(passes), "elapsed_s": float(elapsed)})
        end = float(pb.end_cost(cand.end_xz, np.float64(cand.end_yaw)))
        provenance = [
            (self.db.refs[int(self.db.clip_of[g])], int(g - self.db.clip_start[self.db.clip_of[g]]))
            for g in cand.sigma
        ]
        solution = Solution(
            motion=motion,
            score=cand.score,
            terms={
                "annotation": float(cand.d.sum()),
                "continuity": float(cand.c.sum()),
                "end": end,
            },
            provenance=provenance,
            metrics=metrics,
            annotations=annotations,
        )
        inputs = quality_inputs(self.db, self.frames, pb, cand.sigma, cuts)
        return self.finish(solution, with_loop_goal(inputs) if getattr(request, "loop", False) else inputs)

    def search(self, request: AnnotationRequest, run: Run) -> Stopped:
        """``request.passes`` coarse-to-fine passes (each from a fresh random active set drawn from
        the request's seed), emitting every better motion; the run's time cap and cancel only cut
        the passes short (the first pass always completes). BLAS runs single-threaded
        (:data:`~engines.annotations.build.BLAS_THREADS`), so sums are reduced in one order."""
        with threadpool_limits(limits=BLAS_THREADS):
            self._search(request, run, run.emit)
        return run.outcome()

    def _search(self, request: AnnotationRequest, run: Run, emit: Emitter) -> None:
        state = AnnotationSearch(self.db, request)
        best = float("inf")
        for passes in range(1, int(request.passes) + 1):
            cand = state.one_pass()
            if cand.score < best - 1e-9:
                best = cand.score
                emit.solution(self.solution(cand, state.pb, request, passes, run.elapsed()))
            if passes < request.passes and run.over():
                break
