"""The motion-graph engine as the runtime sees it: ``build`` makes the graph, ``search`` finds paths.

Database kind ``graph`` (:class:`schemas.databases.GraphDatabaseSpec`), request ``engine: "graph"``
(:class:`schemas.graph.GraphRequest`). The build (``build.py``, ``hierarchy.py``) stores the edge
hierarchy and root tracks of :mod:`engines.graph.model` beside the motion library; the search
(``search.py``) walks them and assembles motions (``assemble.py``), emitting every new best; a
request with several ``characters`` is searched jointly by ``shared.py``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

from schemas.databases import DroppedClip, GraphDatabaseSpec, GraphKept
from schemas.graph import GraphRequest

from ..base import (
    Arrays,
    BuildWork,
    DatabaseArrays,
    DatabaseFacts,
    Emitter,
    Engine,
    KindSummary,
    OutputEstimate,
    Run,
    ShouldStop,
    Solution,
    Stopped,
)
from ..library import MotionLibrary, clip_sources, speeds_frames, with_mirrors, with_speeds
from .assemble import pinned_clips
from .build import build_graph, build_work
from .coupled import CoupledSearch
from .model import EdgeTree, FootContacts, RootTracks, compact_motion
from .paths import GraphIndex
from .search import GraphSearch
from .tracks import foot_contacts


class GraphEngine(Engine[GraphRequest, GraphDatabaseSpec]):
    """Randomized anytime search of a hierarchical motion graph (Arikan & Forsyth 2002)."""

    name = "graph"
    kind = "graph"
    request_model = GraphRequest
    spec_model = GraphDatabaseSpec
    summary_arrays = ("graph.report",)

    def __init__(self, library: MotionLibrary, arrays: Arrays) -> None:
        super().__init__(library, arrays)
        self.tree = EdgeTree.from_arrays(arrays)
        self.tracks = RootTracks.from_arrays(arrays)
        GraphIndex.of(self.tree, self.tracks)  # built once per loaded database, not on the first search
        pinned_clips(library)  # likewise (assembly's clips with joint 0 at its usual pose)
        # foot contacts for foot-skate cleanup: stored by the build (older databases: computed here)
        self.contacts = FootContacts.from_arrays(arrays) or foot_contacts(library)

    @classmethod
    def build(
        cls, spec: GraphDatabaseSpec, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop
    ) -> Arrays:
        arrays = build_graph(spec, library, emit, should_stop)
        arrays.update(compact_motion(library.motions))  # stored as float32 (engines.graph.model)
        return arrays

    @classmethod
    def library_for(cls, spec: GraphDatabaseSpec, library: MotionLibrary) -> MotionLibrary:
        """With ``mirror``, the clips followed by their mirror images; with ``speeds``, those followed
        by their time-scaled copies (every mirror image's too: :func:`engines.library.with_speeds`)."""
        return with_speeds(with_mirrors(library) if spec.mirror else library, spec.speeds)

    @classmethod
    def clip_sources(cls, stored_spec: Mapping[str, Any], stored: int) -> list[int | None]:
        """The clips, their mirror images with ``mirror``, then copies of those speed by speed."""
        repeats = (2 if stored_spec.get("mirror") else 1) * (1 + len(stored_spec.get("speeds") or []))
        return clip_sources(len(stored_spec.get("clips") or []), repeats, stored)

    @classmethod
    def library_frames(cls, spec: GraphDatabaseSpec, frames: int) -> int:
        """Twice the clips' frames with ``mirror``; each of ``speeds`` adds ``frames / speed`` of those."""
        return speeds_frames(2 * frames if spec.mirror else frames, spec.speeds)

    @classmethod
    def build_work(cls, spec: GraphDatabaseSpec, frames: int) -> BuildWork:
        return build_work(frames, spec.candidates)

    @classmethod
    def estimate(cls, request: GraphRequest, facts: DatabaseFacts) -> OutputEstimate:
        """``frames``, or ``seconds`` at the output rate, per character; 300 bytes per joint-frame."""
        base = super().estimate(request, facts)
        if request.frames is not None:
            frames = int(request.frames)
        else:
            frames = round(float(request.seconds or 0.0) * base.fps)
        return replace(base, frames=frames, bytes_per_joint_frame=300)

    @classmethod
    def summarize(cls, stored_spec: Mapping[str, Any], arrays: DatabaseArrays) -> KindSummary:
        """What the build kept of the graph and left out (:func:`graph_kept`)."""
        return KindSummary(graph=graph_kept(arrays["graph.report"]) if "graph.report" in arrays else None)

    def search(self, request: GraphRequest, run: Run) -> Stopped:
        emit = run.emit
        note = left_out_note(self.arrays)
        if note is not None:
            emit = _NotingEmitter(emit, note)
        # one BLAS thread: matrix products reduce in one order whatever the machine's cores
        with threadpool_limits(limits=1, user_api="blas"):
            if request.characters:
                # several characters with shared constraints are searched jointly (engines.graph.coupled)
                coupled = self.searcher(request.seed, CoupledSearch)
                return coupled.run(request, run.budget_s, emit, run.should_stop)
            return self.searcher(request.seed).run(request, run.budget_s, emit, run.should_stop)

    def searcher(
        self, seed: int, kind: type[GraphSearch] | type[CoupledSearch] = GraphSearch
    ) -> GraphSearch | CoupledSearch:
        """A search over this database's graph seeded with ``seed`` (benches read its ``rounds_``)."""
        return kind(
            self.library,
            self.tree,
            self.tracks,
            seed,
            contacts=self.contacts,
            reference=self.quality_reference,
            foot_floor=self.foot_floor(self.library.motions[0].skeleton),
        )


def graph_kept(report_json: Any) -> GraphKept | None:
    """The kept-component part of a graph build's report (``graph.report``, 0-d JSON text);
    ``None`` for databases built before the report had it."""
    report = json.loads(str(report_json))
    kept = report.get("kept")
    if kept is None:
        return None
    return GraphKept(
        candidates=report.get("candidates", "all_pairs"),
        leaf_edges=int(report["leaf_edges"]),
        kept_clips=int(kept["clips"]),
        kept_frames=int(kept["frames"]),
        moving_frames=int(kept["moving_frames"]),
        dropped_frames=int(report["dropped_frames"]),
        dropped=[DroppedClip.model_validate(d) for d in report["dropped_clips"]],
    )


def left_out_note(arrays: DatabaseArrays) -> str | None:
    """What a missed goal's report adds when the build left clips out of the graph (their frames
    cannot be played); ``None`` when it kept every clip or the database predates the report."""
    if "graph.report" not in arrays:
        return None
    report = json.loads(str(arrays["graph.report"]))
    dropped = int(report.get("dropped_frames") or 0)
    if not dropped or "kept" not in report:
        return None
    kept = report["kept"]
    return (
        f"the graph plays {kept['frames']} of {kept['frames'] + dropped} frames ({kept['moving_frames']} "
        f"of locomotion): the build left out {len(report['dropped_clips'])} clips ({dropped} frames) "
        "with no transition to or from the rest (see the database's summary.graph); a goal they "
        "alone could reach is out of reach"
    )


class _NotingEmitter:
    """Adds ``note`` to the quality reasons of every solution that misses a goal's position."""

    def __init__(self, inner: Emitter, note: str) -> None:
        self.inner, self.note = inner, note

    def solution(self, solution: Solution) -> str:
        q = solution.quality
        if q is not None and any("from its goal" in r for r in q.reasons) and self.note not in q.reasons:
            q.reasons.append(self.note)
        return self.inner.solution(solution)

    def progress(self, fraction: float, message: str = "") -> None:
        self.inner.progress(fraction, message)
