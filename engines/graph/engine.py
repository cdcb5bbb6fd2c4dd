"""The motion-graph engine as the runtime sees it: ``build`` makes the graph, ``search`` finds paths.

Database kind ``graph`` (:class:`schemas.databases.GraphDatabaseSpec`), request ``engine: "graph"``
(:class:`schemas.graph.GraphRequest`). The build (``build.py``, ``hierarchy.py``) stores the edge
hierarchy and root tracks of :mod:`engines.graph.model` beside the motion library; the search
(``search.py``) walks them and assembles motions (``assemble.py``), emitting every new best; a
request with several ``characters`` is searched jointly by ``shared.py``.
"""

from __future__ import annotations

from typing import Any

from ..base import Arrays, BuildWork, Emitter, Engine, ShouldStop
from ..library import MotionLibrary, with_mirrors
from .build import build_graph, build_work
from .model import EdgeTree, FootContacts, RootTracks
from .paths import GraphIndex
from .search import GraphSearch
from .shared import CoupledSearch
from .tracks import foot_contacts


class GraphEngine(Engine):
    """Randomized anytime search of a hierarchical motion graph (Arikan & Forsyth 2002)."""

    name = "graph"
    kind = "graph"

    def __init__(self, library: MotionLibrary, arrays: Arrays) -> None:
        super().__init__(library, arrays)
        self.tree = EdgeTree.from_arrays(arrays)
        self.tracks = RootTracks.from_arrays(arrays)
        GraphIndex.of(self.tree, self.tracks)  # built once per loaded database, not on the first search
        # foot contacts for foot-skate cleanup: stored by the build (older databases: computed here)
        self.contacts = FootContacts.from_arrays(arrays) or foot_contacts(library)

    @classmethod
    def build(cls, spec: Any, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop) -> Arrays:
        return build_graph(spec, library, emit, should_stop)

    @classmethod
    def library_for(cls, spec: Any, library: MotionLibrary) -> MotionLibrary:
        return with_mirrors(library) if getattr(spec, "mirror", False) else library

    @classmethod
    def build_work(cls, spec: Any, frames: int) -> BuildWork:
        return build_work(frames, spec.candidates)

    def search(self, request: Any, budget_s: float, emit: Emitter, should_stop: ShouldStop) -> None:
        # several characters with shared constraints are searched jointly (engines.graph.shared)
        searcher = CoupledSearch if getattr(request, "characters", None) else GraphSearch
        searcher(
            self.library,
            self.tree,
            self.tracks,
            request.seed,
            contacts=self.contacts,
            reference=self.quality_reference,
            foot_floor=self.foot_floor(self.library.motions[0].skeleton),
        ).run(request, budget_s, emit, should_stop)
