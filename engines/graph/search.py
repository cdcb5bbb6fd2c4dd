"""Randomized anytime search of the hierarchical motion graph (Arikan & Forsyth 2002, Sec. 4.2).

The loop (paper Sec. 4.2, steps 1-6):

1. **Seeds.** Random valid paths in the coarsest graph G' (the edge tree's roots). Without pose
   constraints a seed starts at a random frame (uniform over the frames from which the clip still
   has a root edge ahead or plays long enough: "useful" starts) and walks random root edges (each
   out-edge ahead, or stopping when the clip plays to the end of the output, equally likely)
   until it is long enough; ``seed_batch`` walkers run at once (vectorised) and the best few are
   kept, a greedy choice among random starts. With hard pose constraints a seed is built around
   them: a random backward walk from the first one to a start (root edges, any edge of the tree
   when no root fits), exact-length connections with the fewest cuts between consecutive ones (a
   layered reachability table over (frame, time, cuts), root edges first, sampled backwards at
   random) and a random walk after the last. Half the walkers are *biased*: when their clip
   plays long enough they stop half the time, and they draw edges in proportion to the frames
   the landing clip can still play times ``exp(-cost / median cost)``, so their paths have fewer,
   cheaper cuts.

   **Chain seeds** (no pose constraints; right after the first solution is emitted): every chain
   of 1 to ``chain_edges`` (3) root edges that can play exactly the output length is enumerated
   (at most :data:`MAX_CHAINS` per chain size, a random subset beyond), each with a few lengths
   of its first piece (:data:`CHAIN_STARTS`), and scored in batches cheapest continuity first,
   stopping once the continuity alone exceeds the ``population``-th best score (branch and bound)
   or after :data:`MAX_CHAIN_SCORES` candidates. The :data:`CHAIN_POLISH` best are *polished* together
   by vectorised hill climbing (start slides of :data:`POLISH_SHIFTS` frames, each edge demoted
   to either child; the paths that improved are tried again), and the best distinct clip
   sequences start the population; the next ones (up to :data:`CHAIN_QUEUE`) are the fresh seeds
   of later rounds. On Bandai-Namco locomotion this finds in ~0.2 s CPU scores the random seeds
   alone did not reach in 10 s (``bench/graph.py``).
2. **Mutations** of every path of the population, all enumerated and scored at once
   (:func:`engines.graph.score.score_batch`):

   (a) *replace a sub-path*: for every pair of cut positions ``i <= j``, the edges between them
       are replaced by 0 edges (play on, same clip), 1 root edge or 2 root edges (one hop through
       any clip), wherever that gives a valid path; the tail may also be dropped or replaced
       (open end), and the head may be dropped, the path then starting in the clip of the first
       kept edge so that this cut keeps its time;
   (b) *demote edges*: one edge or two edges at once replaced by their children in the edge
       tree (every combination that stays valid), which refines the cut frames;
   (c) *slide the start* by 1 to 30 frames either way (no pose constraints only: otherwise the
       start is anchored by the first pose).

   With ``staged`` (default) the cheap mutations ((a) with 0 or 1 edge, (b), (c)) are tried
   first and the 2-edge ones only when none of them improves (a variable-neighbourhood descent:
   each step costs a few hundred candidates instead of thousands); at most ``max_candidates``
   2-edge mutations are scored per path and step, a random subset when there are more. The
   1-edge replacements are bounded the same way (at most ``max_one`` per path and step, the
   0-edge ones always kept): they grow with the root edges out of a path's clips, which a large
   library's copies multiply (~2,500 per step at 1M frames, ~1,800 at 400k, ~800 at 100k, ~150
   on ``bench/graph.py``'s database); below the bound nothing is drawn, so the outputs of smaller
   databases do not change (1,500: a bound of 1,000 made the 400k far goal fail its join check
   on one seed more).
3. **Keep** the ``keep`` best improving mutations of each path (distinct paths; a path that plays
   the full length keeps only children that do too); a path with no
   improving mutation is a **local minimum**: it is recorded (best per clip sequence) and leaves
   the population.
4. **Fresh seeds** (``fresh`` per round) join the population, which is capped at ``population``
   paths (the worst older paths go first).

5. **Converge**: the search stops after :data:`PATIENCE` rounds without a better path (the
   paper's "repeat until no better path can be generated"), after the request's ``rounds``, or
   when the budget is spent.

Anytime: every round whose best path improved emits a solution (the first one right after the
first seeds); ``should_stop`` and the time cap are checked every few milliseconds. At the end, the
``request.alternatives`` best distinct local minima (different clip sequences; the population
fills in when there are too few) are emitted after the best one, each with a higher score (the
runtime publishes them as ``alternative`` events, so ``solution`` events stay strictly
improving). All randomness comes from one ``numpy.random.Generator`` seeded with the request's
seed, and every bound on work counts rounds and candidates, not seconds: the search ends by
convergence or after the request's ``rounds`` (:data:`schemas.graph.DEFAULT_ROUNDS` by default),
so the same request and seed return the same motion from the CLI, the HTTP API or any worker, at
any load. ``budget_s`` is only a safety cap: when it cuts the search short, ``run`` returns
``Stopped.budget`` (the ``done`` event and the report say so).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from motion.floorfit import CorrectionLimits
from motion.looping import close_loop, with_loop_goal
from motion.plausibility import Reference
from schemas.graph import GraphRequest

from ..base import Emitter, EngineError, Run, ShouldStop, Solution, Stopped, finish_solution
from ..library import MotionLibrary
from .assemble import assemble, quality_inputs
from .model import EdgeTree, FloatArray, FootContacts, IntArray, RootTracks
from .paths import GraphIndex, Path, PathBatch, batch_valid, clip_sequence, path_pieces, trim
from .score import Evaluation, KeepawayTarget, PoseTarget, Problem, compile_problem, evaluate, score_batch

CHUNK = 1500
"""Candidates scored per call (keeps each call to a few milliseconds)."""
START_SHIFTS = tuple(d for d in range(-30, 31) if d)
"""Start-frame slides tried by mutation (c): every shift up to one second."""
MAX_TABLE = 50_000_000
"""Largest (frames x time steps) reachability table built for pose-to-pose connections."""
POSE_SEEDS = 32
"""Seeds drawn per batch when pose constraints shape them (each is built by a Python loop)."""
MAX_CUTS = 8
"""Most cuts tried between two consecutive pose constraints."""
PATIENCE = 25
"""Rounds without a better path after which the search stops (converged)."""
MAX_CHAIN_SCORES = 150_000
"""Most chain seeds scored (cheapest continuity first): a bound on work, not on time, so the
seeds, and the search after them, are the same on any machine."""
MAX_CHAINS = 150_000
"""Most chains of root edges per chain size enumerated for chain seeds (a random subset beyond)."""
CHAIN_QUEUE = 100
"""Chain seeds kept (distinct clip sequences): the best start the population, the rest wait as
fresh seeds of later rounds."""
CHAIN_STARTS = (0.15, 0.5, 0.85)
CHAIN_RESCORE = 8000
"""Chain seeds scored exactly (best rough scores first) when the exact score needs assembly's
correction estimate (:mod:`engines.graph.fit`)."""
CHAIN_POLISH = 2000
CHAIN_POLISH_EXACT = 250
"""Chain seeds polished when the exact score needs the correction estimate (each costs more)."""
"""Best chain seeds polished by vectorised hill climbing before the population takes them."""
POLISH_SHIFTS = (-20, -10, -5, -2, -1, 1, 2, 5, 10, 20)
"""Start-frame slides tried by the polish."""
POLISH_ROUNDS = 6
"""Hill-climbing steps of the polish."""
"""Where in its feasible range the first piece's length is taken for chain seeds."""


class _Stop(Exception):
    """Raised inside the loop when the time cap is reached or the job is cancelled."""


class _Clock:
    """The search's :class:`~engines.base.Run` as the loop checks it: raises :class:`_Stop`."""

    def __init__(self, run: Run) -> None:
        self.run = run

    def elapsed(self) -> float:
        return self.run.elapsed()

    def check(self) -> None:
        if self.run.over():
            raise _Stop()


class _FirstClock(_Clock):
    """The first seeds are drawn whatever the time cap (only a cancel stops them): a search cut
    short by ``budget_s`` still answers."""

    def check(self) -> None:
        if self.run.cancelled():
            raise _Stop()


@dataclass(slots=True)
class _Member:
    path: Path
    score: float
    born: int


class GraphSearch:
    """Randomized anytime search over a hierarchical motion graph.

    Parameters
    ----------
    library:
        The clips (metres, one rate), in the order the graph indexes them.
    tree, tracks:
        The edge hierarchy and root tracks (:mod:`engines.graph.model`).
    seed:
        Seed of the search's random generator (same seed, same sequence of solutions).
    population, fresh, keep, seed_batch, max_candidates:
        Paths mutated per round, fresh seeds added per round, improving mutations kept per path,
        random seeds drawn per kept seed batch, and candidates scored per path and round.
    max_one:
        Most 1-edge sub-path replacements scored per path and step (a random subset beyond).
    contacts:
        The database's foot contacts, for foot-skate cleanup of the assembled motions (computed
        from the library when not given).
    seed_bias:
        Fraction of random walkers that are biased towards few, cheap cuts (module docstring).
    chain_edges:
        Longest chains of root edges enumerated for chain seeds (0: none).
    patience:
        Rounds without a better path after which the search has converged and stops.
    reference:
        What the database's examples do (:class:`motion.plausibility.Reference`): the physical
        limits of the body-constraint correction and the quality report's reference. ``None``:
        corrections without limit, plausibility reported but not gated.
    foot_floor:
        The examples' foot heights (:meth:`engines.base.Engine.foot_floor`) for foot cleanup.

    Examples
    --------
    >>> GraphSearch(library, tree, tracks, seed=1).run(request, 2.0, emitter, lambda: False)  # doctest: +SKIP
    """

    def __init__(
        self,
        library: MotionLibrary,
        tree: EdgeTree,
        tracks: RootTracks,
        seed: int = 0,
        *,
        population: int = 10,
        fresh: int = 2,
        keep: int = 2,
        seed_batch: int = 256,
        max_candidates: int = 2000,
        max_one: int = 1500,
        start_shifts: tuple[int, ...] = START_SHIFTS,
        staged: bool = True,
        contacts: FootContacts | None = None,
        seed_bias: float = 0.5,
        chain_edges: int = 3,
        patience: int = PATIENCE,
        reference: Reference | None = None,
        foot_floor: dict[int, tuple[float, float]] | None = None,
    ) -> None:
        self.library = library
        self.tree = tree
        self.tracks = tracks
        self.seed = seed
        self.population = population
        self.fresh = fresh
        self.keep = keep
        self.seed_batch = seed_batch
        self.max_candidates = max_candidates
        self.max_one = max_one
        self.start_shifts = start_shifts
        self.staged = staged
        self.contacts = contacts
        self.seed_bias = seed_bias
        self.chain_edges = chain_edges
        self.patience = patience
        self.reference = reference
        self.foot_floor = foot_floor
        self.limits = (
            None if reference is None else CorrectionLimits(reference.root_speed_max, reference.turn_rate_max)
        )
        self.index_ = GraphIndex.of(tree, tracks)
        if self.index_.n_clips != len(library.motions):
            raise EngineError("the graph and the motion library disagree on the clips")
        if self.index_.roots.size == 0:
            raise EngineError("the motion graph has no edges: no transitions to search")
        self._ins: dict[bool, tuple[IntArray, IntArray]] = {}
        self._layer_cache: dict[tuple[int, int, int, bool], list[list[npt.NDArray[np.bool_]]] | None] = {}
        self._useful: IntArray | None = None
        self._cum_weights: FloatArray | None = None
        self._queue: list[_Member] = []
        self._seen: set[tuple[int, int, tuple[int, ...]]] = set()
        self.rounds_ = 0

    # -- public ------------------------------------------------------------------------------
    def run(
        self,
        request: GraphRequest,
        budget_s: float,
        emit: Emitter,
        should_stop: ShouldStop,
        *,
        max_rounds: int | None = None,
        keepaways: tuple[KeepawayTarget, ...] = (),
        warm: Path | None = None,
        cap: Run | None = None,
    ) -> Stopped:
        """Search until the search converges (:attr:`patience` rounds without a better path:
        the paper's "until no better path can be generated") or after ``max_rounds`` rounds (the
        request's ``rounds`` when given), emitting every new best and then the alternatives
        (module docstring); returns why it stopped. ``budget_s`` seconds (or the shared ``cap``)
        and ``should_stop()`` only cut it short: a search that ends by its rounds or convergence
        gives the same result for the same seed on any machine.

        ``keepaways`` (moving keep-out targets), ``warm`` (a path that joins the first seeds, so
        the search returns nothing worse) and ``cap`` (the whole request's time cap) serve the
        coupled search of several characters (:mod:`engines.graph.coupled`); the best path emitted
        is left in :attr:`best_path_`."""
        if request.rounds is not None:
            max_rounds = int(request.rounds)
        run = cap if cap is not None else Run(budget_s, should_stop)
        problem = compile_problem(request, self.library, self.tracks, keepaways)
        self.best_path_: Path | None = None
        rng = np.random.default_rng(self.seed)
        clock = _Clock(run)
        if run.cancelled():
            return run.outcome()
        self._problem = problem
        self._useful = None
        self._seen = set()
        self._queue = []
        self._minima: dict[tuple[int, ...], tuple[float, Path]] = {}
        best: tuple[float, Path] | None = None
        emitted_best: Path | None = None
        population: list[_Member] = []
        try:
            seeds = self._seed_members(problem, rng, self.population, 0, _FirstClock(run))
            if warm is not None:
                ws = score_batch(self.index_, problem, PathBatch.from_paths([warm]))
                if np.isfinite(ws.total[0]):
                    w = trim(self.index_, ws.batch.path(0), problem.length)
                    self._seen.add(w.key)
                    seeds = sorted([*seeds, _Member(w, float(ws.total[0]), 0)], key=lambda m: m.score)
            if not seeds:
                raise EngineError(self._no_seed_message(problem))
            population = seeds
            best = (seeds[0].score, seeds[0].path)
            emitted_best = self._emit(emit, request, best[1], rank=0, local=False)
            if self.chain_edges and not problem.poses:
                population = self._merge(population + self._chain_members(problem, rng, clock))
                if population[0].score < best[0]:
                    best = (population[0].score, population[0].path)
                    emitted_best = self._emit(emit, request, best[1], rank=0, local=False)
            rnd = 0
            last_gain = 0
            while (max_rounds is None or rnd < max_rounds) and rnd - last_gain < self.patience:
                rnd += 1
                self.rounds_ = rnd
                population = self._round(problem, population, rng, rnd, clock)
                if not population:
                    population = self._seed_members(problem, rng, self.population, rnd, clock)
                for m in population:
                    if m.score < best[0]:
                        best = (m.score, m.path)
                for s, p in self._minima.values():
                    if s < best[0]:
                        best = (s, p)
                if best[1] != emitted_best:
                    emitted_best = self._emit(emit, request, best[1], rank=0, local=False)
                    last_gain = rnd
        except _Stop:
            pass
        if best is None:
            return run.outcome()
        for m in population:
            if m.score < best[0]:
                best = (m.score, m.path)
        if best[1] != emitted_best:
            self._emit(emit, request, best[1], rank=0, local=False)
        if run.stopped is Stopped.cancelled or request.alternatives <= 1:
            return run.outcome()
        # the alternatives are part of the answer: emitted whatever the clock says (a cancel stops them)
        for rank, (path, local) in enumerate(
            self._alternatives(problem, best[1], population, request.alternatives), 1
        ):
            if run.cancelled():
                break
            self._emit(emit, request, path, rank=rank, local=local)
        return run.outcome()

    def _merge(self, members: list[_Member]) -> list[_Member]:
        """Distinct paths, best first, at most ``population``."""
        uniq: dict[tuple[int, int, tuple[int, ...]], _Member] = {}
        for m in sorted(members, key=lambda m: m.score):
            uniq.setdefault(m.path.key, m)
        return list(uniq.values())[: self.population]

    # -- chain seeds -------------------------------------------------------------------------
    def _chains(self, length: int, rng: np.random.Generator) -> list[tuple[IntArray, IntArray, IntArray]]:
        """Chains of 1 to ``chain_edges`` root edges that can play exactly ``length`` frames: per
        chain size, ``(edges (N, k) root edge ids, lo (N,), hi (N,))`` with ``[lo, hi]`` the
        frames the first piece may play (at least one frame in every piece, the last cut inside
        the output). Each layer extends the previous one's chains by every root edge leaving the
        landing clip at or after the landing frame, at most :data:`MAX_CHAINS` per layer (a
        random subset beyond)."""
        idx, t = self.index_, self.tree
        roots = idx.roots
        # int64: keys below are clip * span + frame (the stored tree is int32)
        fc, ff = t.from_clip[roots].astype(np.int64), t.from_frame[roots].astype(np.int64)
        tc, tf = t.to_clip[roots].astype(np.int64), t.to_frame[roots].astype(np.int64)
        span = int(idx.frames.max()) + 2
        keys = fc * span + ff
        out: list[tuple[IntArray, IntArray, IntArray]] = []
        chain = np.arange(roots.size, dtype=np.int64)[:, None]  # positions in ``roots``
        mid = np.zeros(roots.size, dtype=np.int64)  # frames of the pieces between first and last
        for k in range(1, self.chain_edges + 1):
            last = chain[:, -1]
            lo = np.maximum(1, length - mid - (idx.frames[tc[last]] - tf[last]))
            hi = np.minimum(ff[chain[:, 0]] + 1, length - mid - 1)
            ok = lo <= hi
            if ok.any():
                out.append((roots[chain[ok]], lo[ok], hi[ok]))
            if k == self.chain_edges:
                break
            # extend: room left for a first piece and a last piece of one frame each
            first = np.searchsorted(keys, tc[last] * span + tf[last], side="left")
            stop = idx._root_start[tc[last] + 1]
            count = np.where(mid + 2 < length, np.maximum(stop - first, 0), 0)
            total = int(count.sum())
            if total == 0:
                break
            # flat indices of the extensions (a random subset when too many, drawn without
            # materialising all of them), then the chain row and the root edge of each
            if total <= MAX_CHAINS:
                flat = np.arange(total)
            else:
                flat = np.sort(rng.integers(total, size=MAX_CHAINS))
                flat = flat[np.concatenate(([True], flat[1:] != flat[:-1]))]
            ends = np.cumsum(count)
            rows = np.searchsorted(ends, flat, side="right")
            nxt = first[rows] + flat - (ends[rows] - count[rows])
            new_mid = mid[rows] + ff[nxt] - tf[chain[rows, -1]] + 1
            fits = new_mid + 2 <= length
            chain = np.concatenate((chain[rows[fits]], nxt[fits, None]), axis=1)
            mid = new_mid[fits]
        return out

    def _chain_members(self, problem: Problem, rng: np.random.Generator, clock: _Clock) -> list[_Member]:
        """Seeds from short chains of root edges (:meth:`_chains`), each with a few first-piece
        lengths, scored cheapest continuity first (branch and bound: a chain's score is at least
        the sum of its edge costs, so the scan stops once that exceeds the ``population``-th best
        score found); the best distinct clip sequences are returned. Bounded by
        :data:`MAX_CHAIN_SCORES` candidates."""
        t = self.tree
        T = problem.length
        w_c = problem.weights["continuity"]
        parts: list[PathBatch] = []
        bounds: list[FloatArray] = []
        for edges, lo, hi in self._chains(T, rng):
            first = edges[:, 0]
            bound = w_c * t.costs(edges).sum(axis=1) if w_c > 0 else np.zeros(edges.shape[0])
            for q in CHAIN_STARTS:
                n0 = np.round(lo + q * (hi - lo)).astype(np.int64)
                parts.append(PathBatch(t.from_clip[first], t.from_frame[first] - n0 + 1, edges))
                bounds.append(bound)
        if not parts:
            return []
        order = np.argsort(np.concatenate(bounds), kind="stable")
        batch = PathBatch.concat(parts).take(order)  # cheapest continuity first
        bound = np.concatenate(bounds)[order]
        rough = problem.grid is not None  # the exact score costs more: rank by the rough one first
        scores = np.full(order.size, np.inf)
        kth = np.inf  # the population-th best score so far
        for c0 in range(0, min(order.size, MAX_CHAIN_SCORES), CHUNK * 4):
            clock.check()
            c1 = min(c0 + CHUNK * 4, order.size, MAX_CHAIN_SCORES)
            if bound[c0] >= kth:
                break
            part = PathBatch(batch.start_clip[c0:c1], batch.start_frame[c0:c1], batch.edges[c0:c1])
            scores[c0:c1] = score_batch(self.index_, problem, part, rough=rough).total
            done = scores[:c1]
            if done.size >= self.population:
                kth = float(np.partition(done, self.population - 1)[self.population - 1])
        if rough:
            keep = np.argsort(scores, kind="stable")[:CHAIN_RESCORE]
            keep = keep[np.isfinite(scores[keep])]
            exact = PathBatch(batch.start_clip[keep], batch.start_frame[keep], batch.edges[keep])
            scores = np.full(order.size, np.inf)
            scores[keep] = self._scores(problem, exact, clock)[0]
        ranked = np.argsort(scores, kind="stable")[: CHAIN_POLISH_EXACT if rough else CHAIN_POLISH]
        ranked = ranked[np.isfinite(scores[ranked])]
        top = PathBatch(batch.start_clip[ranked], batch.start_frame[ranked], batch.edges[ranked])
        top, top_scores = self._polish(problem, top, scores[ranked], clock)
        out: list[_Member] = []
        sequences: set[tuple[int, ...]] = set()
        for r in np.argsort(top_scores, kind="stable"):
            score = float(top_scores[r])
            p = trim(self.index_, top.path(int(r)), T)
            seq = clip_sequence(self.index_, p, T)
            if seq in sequences or p.key in self._seen:
                continue
            sequences.add(seq)
            self._seen.add(p.key)
            out.append(_Member(p, score, 0))
            if len(out) >= CHAIN_QUEUE:
                break
        # the best ones seed the population; the next ones are the first fresh seeds of later rounds
        self._queue = out[self.population :][::-1]
        return out[: self.population]

    def _polish(
        self,
        problem: Problem,
        batch: PathBatch,
        scores: FloatArray,
        clock: _Clock,
        rounds: int = POLISH_ROUNDS,
    ) -> tuple[PathBatch, FloatArray]:
        """A few steps of vectorised hill climbing on a whole batch at once: each path tries its
        start slid by :data:`POLISH_SHIFTS` frames and each edge replaced by either child in the
        edge tree, and takes its best improving neighbour. Returns the improved batch and scores
        (start frames re-anchored as scored)."""
        t = self.tree
        b, m = batch.edges.shape
        batch = PathBatch(batch.start_clip, batch.start_frame.copy(), batch.edges.copy())
        scores = scores.copy()
        active = np.arange(b)  # paths that improved last step (the others sit at a local optimum)
        shifts = np.asarray(POLISH_SHIFTS, dtype=np.int64)
        for _ in range(rounds):
            clock.check()
            # start slides
            rows = [np.repeat(active, shifts.size)]
            sf = [(batch.start_frame[active, None] + shifts[None, :]).reshape(-1)]
            ed = [np.repeat(batch.edges[active], shifts.size, axis=0)]
            # demotions: column j replaced by its left or right child
            for j in range(m):
                e = batch.edges[active, j]
                inner = active[(e >= 0) & (t.left[np.maximum(e, 0)] >= 0)]
                for side in (t.left, t.right):
                    kids = batch.edges[inner].copy()
                    kids[:, j] = side[kids[:, j]]
                    rows.append(inner)
                    sf.append(batch.start_frame[inner])
                    ed.append(kids)
            owner = np.concatenate(rows)
            cand = PathBatch(batch.start_clip[owner], np.concatenate(sf), np.concatenate(ed))
            total, starts = self._scores(problem, cand, clock)
            best = np.full(b, np.inf)
            np.minimum.at(best, owner, total)
            improved = best < scores - 1e-9
            if not improved.any():
                break
            # the first candidate of each owner reaching its best
            hit = np.flatnonzero(total == best[owner])
            first = np.full(b, -1, dtype=np.int64)
            first[owner[hit[::-1]]] = hit[::-1]
            active = np.flatnonzero(improved)
            pick = first[active]
            batch.start_frame[active] = starts[pick]
            batch.edges[active] = cand.edges[pick]
            scores[active] = best[active]
        return batch, scores

    def _scores(self, problem: Problem, cands: PathBatch, clock: _Clock) -> tuple[FloatArray, IntArray]:
        """Totals ``(B,)`` of full-length paths (inf for shorter ones) and their re-anchored
        start frames (:meth:`_scored`)."""
        totals, starts, played = self._scored(problem, cands, clock)
        return np.where(played >= problem.length, totals, np.inf), starts

    def _scored(
        self, problem: Problem, cands: PathBatch, clock: _Clock
    ) -> tuple[FloatArray, IntArray, IntArray]:
        """Totals ``(B,)``, re-anchored start frames and frames played of a batch, scored
        :data:`CHUNK` at a time between budget and cancel checks."""
        totals = np.empty(cands.size)
        starts = np.empty(cands.size, dtype=np.int64)
        played = np.empty(cands.size, dtype=np.int64)
        for lo in range(0, cands.size, CHUNK):
            clock.check()
            hi = min(lo + CHUNK, cands.size)
            part = PathBatch(cands.start_clip[lo:hi], cands.start_frame[lo:hi], cands.edges[lo:hi])
            s = score_batch(self.index_, problem, part)
            totals[lo:hi] = s.total
            starts[lo:hi] = s.batch.start_frame
            played[lo:hi] = s.pieces.total
        return totals, starts, played

    # -- rounds ------------------------------------------------------------------------------
    def _round(
        self, problem: Problem, population: list[_Member], rng: np.random.Generator, rnd: int, clock: _Clock
    ) -> list[_Member]:
        out: list[_Member] = []
        for m in population:
            clock.check()
            if self.staged:
                children = self._best_children(problem, m, self.mutations(m.path, rng, 1), clock)
                if not children:
                    children = self._best_children(problem, m, self.mutations(m.path, rng, 2), clock)
            else:
                children = self._best_children(problem, m, self.mutations(m.path, rng), clock)
            if not children:
                self._record_minimum(problem, m.path, m.score)
                continue
            out.extend(_Member(p, s, m.born) for s, p in children)
        out.extend(self._seed_members(problem, rng, self.fresh, rnd, clock))
        # distinct paths, best first; over the cap, older paths give way to this round's seeds
        uniq: dict[tuple[int, int, tuple[int, ...]], _Member] = {}
        for m in sorted(out, key=lambda m: m.score):
            uniq.setdefault(m.path.key, m)
        members = list(uniq.values())
        if len(members) > self.population:
            new = [m for m in members if m.born == rnd]
            old = [m for m in members if m.born != rnd][: max(self.population - len(new), 0)]
            members = sorted(old + new, key=lambda m: m.score)
        return members

    def _best_children(
        self, problem: Problem, member: _Member, cands: PathBatch, clock: _Clock
    ) -> list[tuple[float, Path]]:
        """The ``keep`` best improving mutations (distinct paths, best first). A path that plays
        the full length only has children that do too (the length term is soft, but a few missing
        frames should not buy a better score once a full-length path is found)."""
        if cands.size == 0:
            return []
        totals, starts, played = self._scored(problem, cands, clock)
        full = path_pieces(self.index_, member.path, problem.length).total >= problem.length
        better = np.flatnonzero((totals < member.score - 1e-9) & (~full | (played >= problem.length)))
        if better.size == 0:
            return []
        order = better[np.argsort(totals[better], kind="stable")]
        kids: list[tuple[float, Path]] = []
        keys = set()
        for i in order:
            p = cands.path(int(i))
            p = trim(self.index_, Path(p.start_clip, int(starts[i]), p.edges), problem.length)
            if p.key in keys:
                continue
            keys.add(p.key)
            kids.append((float(totals[i]), p))
            if len(kids) >= self.keep:
                break
        return kids

    def _record_minimum(self, problem: Problem, path: Path, score: float) -> None:
        key = clip_sequence(self.index_, path, problem.length)
        got = self._minima.get(key)
        if got is None or score < got[0]:
            self._minima[key] = (score, path)

    def _alternatives(
        self, problem: Problem, best: Path, population: list[_Member], k: int
    ) -> list[tuple[Path, bool]]:
        """Up to ``k - 1`` paths after the best: distinct clip sequences, local minima first."""
        taken = {clip_sequence(self.index_, best, problem.length)}
        out: list[tuple[Path, bool]] = []
        for _score, path in sorted(self._minima.values(), key=lambda sp: sp[0]):
            key = clip_sequence(self.index_, path, problem.length)
            if key not in taken and len(out) < k - 1:
                taken.add(key)
                out.append((path, True))
        for m in sorted(population, key=lambda m: m.score):
            key = clip_sequence(self.index_, m.path, problem.length)
            if key not in taken and len(out) < k - 1:
                taken.add(key)
                out.append((m.path, False))
        return out

    # -- emission ----------------------------------------------------------------------------
    def _emit(self, emit: Emitter, request: GraphRequest, path: Path, *, rank: int, local: bool) -> Path:
        ev = evaluate(self.index_, self._problem, path)
        if rank == 0:
            self.best_path_ = ev.path
        emit.solution(self.solution(ev, request, rank=rank, local=local))
        return path

    def solution(
        self, ev: Evaluation, request: GraphRequest, *, rank: int = 0, local: bool = False
    ) -> Solution:
        """The :class:`~engines.base.Solution` of an evaluated path (assembled motion, quality report)."""
        motion, provenance = assemble(
            self.library,
            self.tracks,
            ev.pieces,
            ev.placement,
            request,
            self._problem,
            contacts=self.contacts,
            feet=request.feet_mode() != "free",
            lock=request.feet_mode() == "lock",
            limits=self.limits,
            floor=self.foot_floor,
        )
        if getattr(request, "loop", False):
            motion = close_loop(motion)
        cuts = ev.pieces.start[1:]
        cuts = cuts[(cuts > 0) & (cuts < motion.num_frames)]
        inputs = quality_inputs(motion, provenance, cuts, self._problem, self.library)
        if getattr(request, "loop", False):
            inputs = with_loop_goal(inputs)
        metrics = {
            "pieces": float(ev.pieces.clip.size),
            "alternative": float(rank),
            "local_minimum": float(local),
            "search_rounds": float(self.rounds_),
        }
        solution = Solution(
            motion=motion,
            score=ev.score,
            terms=dict(ev.terms),
            provenance=provenance,
            metrics=metrics,
        )
        return finish_solution(solution, inputs, self.reference)

    # -- mutations ---------------------------------------------------------------------------
    def mutations(self, path: Path, rng: np.random.Generator, stage: int | None = None) -> PathBatch:
        """The mutations of a path (module docstring), as one batch: ``stage`` 1 the cheap ones
        ((a) with 0 or 1 edge, (b), (c); at most ``max_one`` 1-edge ones), 2 the (a) 2-edge ones
        (at most ``max_candidates``), ``None`` all of them (2-edge ones filling up to
        ``max_candidates``).

        For each kept head ``edges[:i]`` (reaching clip ``A`` at frame ``x``), the replacements
        leading to every later edge ``edges[j]`` (leaving clip ``B`` at frame ``y``) are found at
        once: ``(root edge or edge pair) x (j)`` boolean tables of "ends in B no later than y"."""
        idx = self.index_
        t = self.tree
        edges = np.asarray(path.edges, dtype=np.int64)
        n = edges.size
        node_clip = np.concatenate(([path.start_clip], t.to_clip[edges])).astype(np.int64)
        node_frame = np.concatenate(([path.start_frame], t.to_frame[edges])).astype(np.int64)
        tgt_clip, tgt_frame = t.from_clip[edges], t.from_frame[edges]
        one: list[tuple[IntArray, IntArray, IntArray]] = []
        two: list[tuple[IntArray, IntArray, IntArray]] = []
        none = np.full((1, 2), -1, dtype=np.int64)
        for i in range(n + 1):
            a_clip, x = int(node_clip[i]), int(node_frame[i])
            js = np.arange(i, n)
            b_clip, y = tgt_clip[i:], tgt_frame[i:]
            if stage != 2:
                # 0 edges: play on to a later edge of the same clip, or to the end (drop the tail)
                j0 = js[(js > i) & (b_clip == a_clip) & (y >= x)]
                if i < n:
                    j0 = np.append(j0, n)
                if j0.size:
                    one.append((np.full(j0.size, i), j0, np.repeat(none, j0.size, axis=0)))
                # 1 root edge
                h = idx.root_out(a_clip, x)
                if h.size:
                    ok = (t.to_clip[h][:, None] == b_clip[None, :]) & (t.to_frame[h][:, None] <= y[None, :])
                    if i + 1 < n:
                        ok[:, 1] &= h != edges[i]
                    hk, jk = np.nonzero(ok)
                    tail = h if i != n - 1 else h[h != edges[n - 1]]
                    rr = np.full((hk.size + tail.size, 2), -1, dtype=np.int64)
                    rr[:, 0] = np.concatenate((h[hk], tail))
                    one.append((np.full(rr.shape[0], i), np.concatenate((js[jk], np.full(tail.size, n))), rr))
            if stage != 1:
                # 2 root edges (one hop through any clip)
                h1, h2 = idx.two_hops(a_clip, -1)
                keep = t.from_frame[h1] >= x
                h1, h2 = h1[keep], h2[keep]
                if h1.size:
                    ok = (t.to_clip[h2][:, None] == b_clip[None, :]) & (t.to_frame[h2][:, None] <= y[None, :])
                    if i + 2 < n:
                        ok[:, 2] &= ~((h1 == edges[i]) & (h2 == edges[i + 1]))
                    hk, jk = np.nonzero(ok)
                    rr = np.stack((np.concatenate((h1[hk], h1)), np.concatenate((h2[hk], h2))), axis=1)
                    two.append((np.full(rr.shape[0], i), np.concatenate((js[jk], np.full(h1.size, n))), rr))
        batches: list[PathBatch] = []
        if one:
            a1, b1, r1 = (np.concatenate(v) for v in zip(*one, strict=True))
            hops = np.flatnonzero(r1[:, 0] >= 0)  # the 1-edge ones (the rest play on: 0 edges)
            if hops.size > self.max_one:
                pick = rng.choice(hops.size, size=self.max_one, replace=False)
                keep = np.ones(a1.size, dtype=bool)
                keep[hops] = False
                keep[hops[pick]] = True
                a1, b1, r1 = a1[keep], b1[keep], r1[keep]
            batches.append(self._splice(path, a1, b1, r1))
        if stage != 2:
            batches.append(self._demotions(path))
            if not self._problem.poses:
                batches.append(self._start_moves(path))
        fixed = sum(b.size for b in batches)
        if two:
            a2, b2, r2 = (np.concatenate(v) for v in zip(*two, strict=True))
            room = max(self.max_candidates - fixed, 0)
            if a2.size > room:
                pick = np.sort(rng.choice(a2.size, size=room, replace=False))
                a2, b2, r2 = a2[pick], b2[pick], r2[pick]
            if a2.size:
                batches.append(self._splice(path, a2, b2, r2))
        return PathBatch.concat([b for b in batches if b.size])

    def _splice(self, path: Path, a: IntArray, b: IntArray, r: IntArray) -> PathBatch:
        """Paths ``edges[:a] + r + edges[b:]`` (``r`` padded with -1), vectorised."""
        edges = np.asarray(path.edges, dtype=np.int64)
        n = edges.size
        nr = (r >= 0).sum(axis=1)
        new_n = a + nr + (n - b)
        m = int(new_n.max(initial=0))
        col = np.arange(m)[None, :]
        padded = np.concatenate((edges, [-1]))
        a_, b_, nr_ = a[:, None], b[:, None], nr[:, None]
        from_prefix = padded[np.minimum(col, n)]
        from_r = np.take_along_axis(r, np.clip(col - a_, 0, 1), axis=1)
        from_suffix = padded[np.clip(b_ + col - a_ - nr_, 0, n)]
        out = np.where(col < a_, from_prefix, np.where(col < a_ + nr_, from_r, from_suffix))
        out = np.where(col < new_n[:, None], out, -1)
        k = a.size
        start_clip = np.full(k, path.start_clip, dtype=np.int64)
        start_frame = np.full(k, path.start_frame, dtype=np.int64)
        # a head replaced by nothing (a == 0, no edges in r) keeps the start clip: play on from it
        return PathBatch(start_clip, start_frame, out.astype(np.int64))

    def _demotions(self, path: Path) -> PathBatch:
        """Mutation (b): one or two edges replaced by children (every combination)."""
        t = self.tree
        edges = np.asarray(path.edges, dtype=np.int64)
        inner = [i for i in range(edges.size) if t.left[edges[i]] >= 0]
        rows: list[np.ndarray] = []
        for ii, i in enumerate(inner):
            kids_i = (t.left[edges[i]], t.right[edges[i]])
            for ci in kids_i:
                row = edges.copy()
                row[i] = ci
                rows.append(row)
            for k in inner[ii + 1 :]:
                for ci in kids_i:
                    for ck in (t.left[edges[k]], t.right[edges[k]]):
                        row = edges.copy()
                        row[i], row[k] = ci, ck
                        rows.append(row)
        if not rows:
            return PathBatch(
                np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, edges.size), np.int64)
            )
        mat = np.stack(rows)
        k = mat.shape[0]
        out = PathBatch(np.full(k, path.start_clip, np.int64), np.full(k, path.start_frame, np.int64), mat)
        return out.take(np.flatnonzero(batch_valid(self.index_, out)))  # children may break the chain

    def _start_moves(self, path: Path) -> PathBatch:
        """Mutation (c): the start slid by a few frames; and heads dropped (start re-chosen in the
        clip of a later edge so that this edge's cut keeps its output time)."""
        t = self.tree
        idx = self.index_
        edges = np.asarray(path.edges, dtype=np.int64)
        limit = int(t.from_frame[edges[0]]) if edges.size else int(idx.frames[path.start_clip]) - 1
        shifts = np.array(
            [path.start_frame + d for d in self.start_shifts if 0 <= path.start_frame + d <= limit]
        )
        clips = [np.full(shifts.size, path.start_clip)]
        frames = [shifts]
        rows = [np.tile(edges, (shifts.size, 1))]
        if edges.size > 1:
            # output time of the cut of each edge
            pieces_end = np.concatenate(
                (
                    [t.from_frame[edges[0]] - path.start_frame + 1],
                    t.from_frame[edges[1:]] - t.to_frame[edges[:-1]] + 1,
                )
            )
            cut_time = np.cumsum(pieces_end)
            for j in range(1, edges.size):
                f0 = int(t.from_frame[edges[j]]) - int(cut_time[j]) + 1
                if f0 >= 0:
                    clips.append(np.array([t.from_clip[edges[j]]]))
                    frames.append(np.array([f0]))
                    row = np.full(edges.size, -1, dtype=np.int64)
                    row[: edges.size - j] = edges[j:]
                    rows.append(row[None, :])
        return PathBatch(
            np.concatenate(clips).astype(np.int64),
            np.concatenate(frames).astype(np.int64),
            np.concatenate(rows).astype(np.int64),
        )

    # -- seeds -------------------------------------------------------------------------------
    def _seed_members(
        self, problem: Problem, rng: np.random.Generator, count: int, rnd: int, clock: _Clock
    ) -> list[_Member]:
        """The ``count`` best of ``seed_batch`` random seeds not seen before, best first."""
        if count <= 0:
            return []
        if self._queue:
            queued = [self._queue.pop() for _ in range(min(count, len(self._queue)))]
            return [_Member(m.path, m.score, rnd) for m in queued]
        if problem.poses:
            tries = min(self.seed_batch, POSE_SEEDS)  # built one by one in Python
            paths = [p for p in (self._pose_seed(rng) for _ in range(tries)) if p is not None]
            if not paths:
                return []
            batch = PathBatch.from_paths(paths)
        else:
            batch = self._random_seeds(rng, self.seed_batch, self.seed_bias)
        clock.check()
        s = score_batch(self.index_, problem, batch)
        order = np.argsort(s.total, kind="stable")
        out: list[_Member] = []
        for i in order:
            if not np.isfinite(s.total[i]):
                break
            p = trim(self.index_, s.batch.path(int(i)), problem.length)
            if p.key in self._seen:
                continue
            self._seen.add(p.key)
            out.append(_Member(p, float(s.total[i]), rnd))
            if len(out) >= count:
                break
        return out

    def _edge_weights(self) -> FloatArray:
        """``(R + 1,)`` cumulative sampling weights of the sorted root edges for biased walkers:
        frames the landing clip can still play, times ``exp(-cost)`` (long, cheap pieces first)."""
        if self._cum_weights is None:
            t, roots = self.tree, self.index_.roots
            play = (self.index_.frames[t.to_clip[roots]] - t.to_frame[roots]).astype(np.float64)
            cost = t.costs(roots)
            w = np.maximum(play, 1.0) * np.exp(-cost / max(float(np.median(cost)), 1e-9))
            self._cum_weights = np.concatenate(([0.0], np.cumsum(w)))
        return self._cum_weights

    def _random_seeds(self, rng: np.random.Generator, count: int, biased: float = 0.0) -> PathBatch:
        """``count`` random walks at once (module docstring), as a batch.

        Root edges are sorted by ``(from clip, from frame)``, so the edges a walker may take next
        (leaving its clip at or after its frame, with the cut inside the output) are one
        contiguous range found by binary search; each walker picks one of them or, when its clip
        plays long enough, stops, all options equally likely."""
        idx, t = self.index_, self.tree
        T = self._problem.length
        if self._useful is None:
            last_out = np.full(idx.n_clips, -1, dtype=np.int64)
            np.maximum.at(last_out, t.from_clip[idx.roots], t.from_frame[idx.roots])
            useful = np.minimum(np.maximum(last_out + 1, idx.frames - T + 1), idx.frames)
            self._useful = np.cumsum(np.maximum(useful, 0))
        total = int(self._useful[-1])
        if total == 0:
            return PathBatch(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 0), np.int64))
        g = rng.integers(total, size=count)
        clip = np.searchsorted(self._useful, g, side="right").astype(np.int64)
        frame = g - np.where(clip > 0, self._useful[np.maximum(clip - 1, 0)], 0)
        start_clip, start_frame = clip.copy(), frame.copy()
        roots = idx.roots
        span = int(idx.frames.max()) + 2
        keys = t.from_clip[roots].astype(np.int64) * span + t.from_frame[roots]
        now = np.zeros(count, dtype=np.int64)
        active = np.ones(count, dtype=bool)
        bias = np.arange(count) < round(biased * count)
        cols: list[IntArray] = []
        while active.any() and len(cols) <= T:
            enough = now + idx.frames[clip] - frame >= T
            lo = np.searchsorted(keys, clip * span + frame, side="left")
            # the cut must fall inside the output: from_frame - frame + now < T - 1
            limit = np.clip(T - 1 - now + frame, 0, span - 1)
            hi = np.maximum(np.searchsorted(keys, clip * span + limit, side="left"), lo)
            options = hi - lo + enough
            u = rng.random(count)
            k = np.floor(u * np.maximum(options, 1)).astype(np.int64)
            if bias.any():
                # biased walkers: stop half the time when the clip plays long enough, else an edge
                # drawn by weight (long remaining play, low cost) from the same range
                cw = self._edge_weights()
                stop = enough & (u < 0.5)
                v = rng.random(count)
                pick = np.searchsorted(cw, cw[lo] + v * (cw[hi] - cw[lo]), side="right") - 1 - lo
                pick = np.clip(pick, 0, np.maximum(hi - lo - 1, 0))
                kb = np.where(stop | (hi == lo), hi - lo, pick)
                k = np.where(bias, kb, k)
            take = active & (options > 0) & (k < hi - lo)
            e = np.where(take, roots[np.minimum(lo + k, roots.size - 1)], -1)
            cols.append(e)
            te = np.maximum(e, 0)
            now = np.where(take, now + t.from_frame[te] - frame + 1, now)
            clip = np.where(take, t.to_clip[te], clip)
            frame = np.where(take, t.to_frame[te], frame)
            active = take
        edges = np.stack(cols, axis=1) if cols else np.zeros((count, 0), np.int64)
        width = int((edges >= 0).sum(axis=1).max(initial=0))
        return PathBatch(start_clip, start_frame, np.ascontiguousarray(edges[:, :width]))

    def _walk(self, rng: np.random.Generator, clip: int, frame: int, time_out: int) -> list[int]:
        """Random root edges from ``(clip, frame)`` playing at output frame ``time_out`` until
        the output length is reached (or a dead end)."""
        idx, t = self.index_, self.tree
        T = self._problem.length
        out: list[int] = []
        for _ in range(T + 1):
            enough = time_out + (int(idx.frames[clip]) - frame) >= T
            h = idx.root_out(clip, frame)
            h = h[t.from_frame[h] - frame + time_out < T - 1]
            options = h.size + int(enough)
            if options == 0:
                break
            k = int(rng.integers(options))
            if k == h.size:
                break
            e = int(h[k])
            out.append(e)
            time_out += int(t.from_frame[e]) - frame + 1
            clip, frame = int(t.to_clip[e]), int(t.to_frame[e])
        return out

    def _in_edges(self, every: bool) -> tuple[IntArray, IntArray]:
        """Root edges (or every edge of the tree) sorted by (to clip, to frame), and ``(C + 1,)``
        where each clip's run of them starts."""
        got = self._ins.get(every)
        if got is None:
            r = np.arange(self.tree.size, dtype=np.int64) if every else self.index_.roots
            edges = r[np.lexsort((self.tree.to_frame[r], self.tree.to_clip[r]))]
            starts = np.searchsorted(
                self.tree.to_clip[edges], np.arange(self.index_.n_clips + 1), side="left"
            )
            got = (edges, starts.astype(np.int64))
            self._ins[every] = got
        return got

    def _arrivals(self, clip: int, frame: int, now: int, every: bool) -> IntArray:
        """Edges into ``clip`` at a frame ``<= frame`` that leave at least one output frame before
        (``frame - to_frame < now``)."""
        t = self.tree
        ins, starts = self._in_edges(every)
        cand = ins[int(starts[clip]) : int(starts[clip + 1])]
        return cand[(t.to_frame[cand] <= frame) & (t.to_frame[cand] >= frame - now + 1)]

    def _pose_seed(self, rng: np.random.Generator) -> Path | None:
        """A random path through every pose constraint at its time (module docstring)."""
        problem = self._problem
        t = self.tree
        poses: list[PoseTarget] = []
        for p in problem.poses:
            if not poses or poses[-1].frame != p.frame:
                poses.append(p)
        # backwards from the first pose to a start: random root edges (any edge when no root fits)
        clip, frame, now = poses[0].clip, poses[0].clip_frame, poses[0].frame
        head: list[int] = []
        for _ in range(problem.length + 1):
            can_start = frame >= now
            if can_start and rng.random() < 0.5:
                break
            cand = self._arrivals(clip, frame, now, every=False)
            if cand.size == 0:
                cand = self._arrivals(clip, frame, now, every=True)
            if cand.size == 0:
                if can_start:
                    break
                return None
            e = int(cand[rng.integers(cand.size)])
            head.append(e)
            now -= frame - int(t.to_frame[e]) + 1
            clip, frame = int(t.from_clip[e]), int(t.from_frame[e])
        else:
            return None
        edges = head[::-1]
        for a, b in itertools.pairwise(poses):
            link = self._connect(a.clip, a.clip_frame, b.clip, b.clip_frame, b.frame - a.frame, rng)
            if link is None:
                return None
            edges.extend(link)
        last = poses[-1]
        edges.extend(self._walk(rng, last.clip, last.clip_frame, last.frame))
        return Path(clip, frame - now, tuple(edges))

    def _layers(self, g1: int, g2: int, steps: int, every: bool) -> list[list[npt.NDArray[np.bool_]]] | None:
        """``layers[k][s][g]``: library frame ``g`` can play ``s`` output frames after frame ``g1``
        with at most ``k`` cuts (root edges, or every edge of the tree), up to the fewest cuts
        that reach ``g2`` after ``steps`` frames; ``None`` when :data:`MAX_CUTS` cuts do not."""
        key = (g1, g2, steps, every)
        if key in self._layer_cache:
            return self._layer_cache[key]
        t = self.tree
        off = self.tracks.offsets
        n = int(off[-1])
        if steps * n > MAX_TABLE:
            raise EngineError(f"pose constraints {steps} frames apart are too far apart to connect exactly")
        edges = np.arange(t.size) if every else self.index_.roots
        g_from = off[t.from_clip[edges]] + t.from_frame[edges]
        g_to = off[t.to_clip[edges]] + t.to_frame[edges]
        cont = np.ones(n, dtype=bool)
        cont[off[:-1]] = False  # frame g - 1 plays on to g (same clip)
        layers: list[list[npt.NDArray[np.bool_]]] = []
        found: list[list[npt.NDArray[np.bool_]]] | None = None
        for k in range(MAX_CUTS + 1):
            cur = np.zeros(n, dtype=bool)
            cur[g1] = True
            level = [cur]
            for s in range(1, steps + 1):
                nxt = np.zeros(n, dtype=bool)
                nxt[1:] = cur[:-1] & cont[1:]
                if k:
                    nxt[g_to[layers[k - 1][s - 1][g_from]]] = True
                level.append(nxt)
                cur = nxt
            layers.append(level)
            if cur[g2]:
                found = layers
                break
        self._layer_cache[key] = found
        return found

    def _connect(
        self, c1: int, k1: int, c2: int, k2: int, steps: int, rng: np.random.Generator
    ) -> list[int] | None:
        """Random edges taking clip frame ``(c1, k1)`` to ``(c2, k2)`` in exactly ``steps`` output
        frames with the fewest cuts (root edges when they can, else any edge of the tree); ``None``
        when impossible. Sampled backwards through the layered reachability table, each step
        choosing at random among the moves (play on, or an edge) that keep the fewest cuts."""
        t = self.tree
        off = self.tracks.offsets
        g1, g2 = int(off[c1] + k1), int(off[c2] + k2)
        layers = None
        for every in (False, True):
            layers = self._layers(g1, g2, steps, every)
            if layers is not None:
                break
        if layers is None:
            return None
        edges = np.arange(t.size) if every else self.index_.roots
        g_from = off[t.from_clip[edges]] + t.from_frame[edges]
        g_to = off[t.to_clip[edges]] + t.to_frame[edges]
        by_to = np.argsort(g_to, kind="stable")
        sorted_to = g_to[by_to]
        starts = {int(o) for o in off[:-1]}
        k = len(layers) - 1
        g = g2
        rev: list[int] = []
        for s in range(steps, 0, -1):
            play = g not in starts and bool(layers[k][s - 1][g - 1])
            jumps = np.zeros(0, dtype=np.int64)
            if k:
                lo, hi = np.searchsorted(sorted_to, g, "left"), np.searchsorted(sorted_to, g, "right")
                jumps = by_to[lo:hi]
                jumps = jumps[layers[k - 1][s - 1][g_from[jumps]]]
            pick = int(rng.integers(jumps.size + int(play)))
            if pick == jumps.size:
                g -= 1
                continue
            j = int(jumps[pick])
            rev.append(int(edges[j]))
            g = int(g_from[j])
            k -= 1
        return rev[::-1]

    def _no_seed_message(self, problem: Problem) -> str:
        if problem.poses:
            names = ", ".join(
                f"{p.name} ({self.library.names[p.clip]} frame {p.clip_frame} at {p.frame})"
                for p in problem.poses
            )
            t = self.tree
            isolated = sorted(
                {
                    self.library.names[p.clip]
                    for p in problem.poses
                    if not np.any(t.from_clip == p.clip) and not np.any(t.to_clip == p.clip)
                }
            )
            why = (
                f"; clip(s) {', '.join(isolated)} have no transition in the graph (dropped by the build)"
                if isolated
                else ""
            )
            return f"no path of the graph meets the pose constraints {names}{why}"
        return "no valid path found in the motion graph"
