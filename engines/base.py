"""What every engine shares: the solution type and the interfaces between engines and the runtime.

Engines follow the estimator style of DESIGN.md: a database object is built once from a motion
library (:mod:`engines.library`) and stored as arrays; a loaded engine then answers
``search(request, run)``, calling ``run.emit.solution`` every time its best score improves
(anytime) and asking ``run.over()`` between units of work (cancel, time cap). Engines never
import the service, the workers or Redis.

Every search is bounded by *work* derived from the request (the graph's rounds, the annotation
engine's passes, the control engine's stages, the rhythm engine's single pass), never by the
clock, so a request and its seed give the same bytes on any machine and at any load. The time
budget ``budget_s`` is only a safety cap: a :class:`Run` carries the emitter, the time cap and the
cancel flag, and ``search`` returns why it stopped (:class:`Stopped`), which the runtime puts in the ``done``
event and the report.

This module, :mod:`engines.registry` and the package itself are all the workers and the service
may import of the engines (``tests/test_layering.py``). An engine is the one place that knows its
requests and databases: :class:`Engine` is generic in its request and spec models
(``Engine[RequestT, SpecT]``, named by ``request_model``/``spec_model``) and answers, besides
``build`` and ``search(request, run)``, what the runtime asks of it -- :meth:`Engine.estimate`
(the output a request asks for, for work budgets), :meth:`Engine.summarize` (its part of a
database's summary) -- and the query API a route needs of a database: :meth:`Engine.clip_labels`
and :meth:`Engine.corrected_spec` read a few arrays of a lazily opened database file
(:func:`open_database`, :mod:`engines.container`), :meth:`Engine.movement_graph` and
:meth:`Engine.edit_movement_graph` read and derive a movement graph, :meth:`Engine.live_session`
starts a :class:`LiveSession`. A query an engine cannot answer raises :class:`EngineError`.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, ClassVar, Generic, Literal, Protocol, TypeAlias, TypeVar

import numpy as np
import numpy.typing as npt

from motion import Motion, MotionError, Skeleton
from motion.errors import ReadWarning
from motion.plausibility import Reference, reference_from_positions
from motion.quality import QualityInputs, QualityReport, assess
from schemas.annotations import ClipLabels, LabelCorrection
from schemas.bases import DatabaseSpecBase, JobRequestBase
from schemas.databases import GraphKept
from schemas.movement_graph import DerivedFrom, GraphEdits, MovementGraph, ResolvedEdit

from . import container as container  # the database file format, for the store
from .library import ClipInput as ClipInput  # a clip as read, for the runtime that reads them
from .library import MotionLibrary as MotionLibrary  # what a database is built from
from .library import build_library, clip_sources, library_from_arrays, library_to_arrays
from .progress import PhasedProgress

BUILD_PHASES = {"library": 0.1, "kind": 0.95}
"""Where a database build's phases end, as overall fractions: reading the clips into the motion
library up to 0.1, the kind's own build (named after the kind) up to 0.95, then the examples'
quality reference (the runtime reports 1.0, "built", once the arrays are stored)."""

Arrays = dict[str, npt.NDArray[Any]]
ShouldStop = Callable[[], bool]
DatabaseArrays = Mapping[str, npt.NDArray[Any]]
"""A database's arrays by name, possibly read lazily (:func:`open_database`)."""
Array = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class BuildWork:
    """What a database build is expected to take: CPU seconds (all threads) and peak resident
    memory (MiB) of the build job."""

    cpu_s: float
    memory_mb: float


@contextmanager
def open_database(path: str | Path | DatabaseArrays) -> Iterator[DatabaseArrays]:
    """The arrays of a built database, each read only when indexed.

    ``path`` is a database directory (``arrays.json`` + one ``.npy`` per array,
    :mod:`engines.container`: large arrays are memory-mapped), a legacy ``data.npz`` file (a zip of
    ``.npy`` members: indexing reads that member) or a directory holding one, or a mapping of
    arrays already opened (e.g. by the store, from an object store), passed through. A query that
    needs a few small arrays (clip names, frame counts, labels) reads those and leaves the motion
    and the engine's tables where they are. Raises ``OSError`` when nothing can be read.
    """
    if isinstance(path, Mapping):
        yield path
        return
    p = Path(path)
    if p.is_dir() and (p / container.MANIFEST).is_file():
        yield container.open_arrays(p)
        return
    if p.is_dir():
        p = p / "data.npz"
    with np.load(p, allow_pickle=False) as arrays:
        yield arrays


class Stopped(StrEnum):
    """Why a search ended (the ``stopped`` of the ``done`` event and of the report)."""

    work = "work"
    """It did the work the request asked for (or converged before): the answer depends only on
    the request and its seed."""
    budget = "budget"
    """The time cap ``budget_s`` cut it short: the answer is the best found so far and may differ
    from an unhurried run's (and from machine to machine)."""
    cancelled = "cancelled"
    """The job was cancelled (``should_stop``)."""

    @property
    def reason(self) -> str:
        """One line for users saying what the stop means for the answer."""
        return _STOP_REASONS[self]


_STOP_REASONS = {
    Stopped.work: "the search did all the work the request asked for: the same request and seed "
    "give the same answer on any machine",
    Stopped.budget: "the time cap (budget_s) cut the search short before the work the request asked "
    "for was done: the answer is the best found so far and may differ from an unhurried run's; "
    "raise budget_s or lower the work (rounds, passes) for a reproducible answer",
    Stopped.cancelled: "the job was cancelled: the answer is the best found so far",
}


CLOCK: Callable[[], float] = time.perf_counter
"""The clock :class:`Run` measures its time cap on (seconds; tests patch it)."""


class Run:
    """One search's runtime: where it reports (``emit``), its bounds (the cancel flag, the time
    cap) and why it stopped.

    Engines bound their work by the request (rounds, passes, stages) and ask :meth:`over` between
    units of work; the first time the cap or the cancel flag ends the search, :attr:`stopped`
    records why (:class:`Stopped`), and :meth:`outcome` is what ``search`` returns
    (``Stopped.work`` when nothing cut it short).

    ``budget_s`` seconds are counted on :data:`CLOCK` (``time.perf_counter``; tests patch it to
    simulate a slow machine) from when the run is made; ``should_stop`` is polled at most every
    ``poll_s`` seconds (it may be a Redis round trip). ``emit`` gets every solution and progress
    report (default: a :class:`CollectingEmitter`, for running engines straight from Python).

    Example
    -------
    >>> run = Run(10.0)
    >>> for _ in range(3):
    ...     if run.over():
    ...         break
    >>> run.outcome()
    <Stopped.work: 'work'>
    """

    __slots__ = (
        "_last_poll",
        "budget_s",
        "clock",
        "deadline",
        "emit",
        "poll_s",
        "should_stop",
        "stopped",
        "t0",
    )

    def __init__(
        self,
        budget_s: float,
        should_stop: ShouldStop = lambda: False,
        emit: Emitter | None = None,
        *,
        poll_s: float = 0.005,
    ) -> None:
        self.clock: Callable[[], float] = CLOCK
        self.budget_s = float(budget_s)
        self.should_stop = should_stop
        self.emit: Emitter = CollectingEmitter() if emit is None else emit
        self.poll_s = poll_s
        self.t0 = self.clock()
        self.deadline = self.t0 + self.budget_s
        self.stopped: Stopped | None = None
        self._last_poll = -np.inf

    def elapsed(self) -> float:
        """Seconds since the run started (reports only: never a bound on work)."""
        return self.clock() - self.t0

    def out_of_time(self) -> bool:
        """Whether the time cap is reached (recorded as the stop reason)."""
        if self.stopped is not None:
            return True
        if self.clock() >= self.deadline:
            self.stopped = Stopped.budget
            return True
        return False

    def cancelled(self) -> bool:
        """Whether the job is cancelled (polled now, recorded as the stop reason)."""
        if self.stopped is Stopped.cancelled:
            return True
        if self.should_stop():
            self.stopped = Stopped.cancelled
            return True
        return False

    def over(self) -> bool:
        """Whether the search must stop now: cancelled (polled every ``poll_s``) or out of time."""
        if self.stopped is not None:
            return True
        now = self.clock()
        if now - self._last_poll >= self.poll_s:
            self._last_poll = now
            if self.cancelled():
                return True
        return self.out_of_time()

    def outcome(self) -> Stopped:
        """Why the search ended: the recorded reason, else ``Stopped.work``."""
        return self.stopped or Stopped.work


class LiveControlSession(Protocol):
    """A target an engine generates while its control streams in (the control engine's live
    follower or walker): control frames in, the target frames that became final out."""

    frame: int
    """Target frames sent so far."""
    solves: int
    """Windows solved so far."""

    def hello_message(self) -> dict[str, Any]:
        """The first message of a session: the skeleton, rates, latency and the control expected."""
        ...

    def push(self, frames: Any) -> dict[str, Any]:
        """Append control frames; the ``frames`` message of the target frames now final."""
        ...

    def finish(self) -> dict[str, Any]:
        """The control has ended: the remaining target frames."""
        ...


class LiveSession(Protocol):
    """A character an engine animates as events arrive (the rhythm engine's live dancer): one
    batch of frames per beat, steered between beats."""

    frame: int
    """Frames sent so far."""
    beats: int
    """Beats danced so far."""

    @property
    def period_s(self) -> float:
        """The examples' beat period, seconds (the beat clock's default)."""
        ...

    def skeleton_message(self) -> dict[str, Any]:
        """The first message of a session: the skeleton and the rate of the frames to come."""
        ...

    def steer(self, heading_deg: float | None, speed: float | None) -> None:
        """Steer from the next movement (``None``: dance freely)."""
        ...

    def beat(self, period_s: float) -> dict[str, Any]:
        """The frames of the beat that starts now, lasting ``period_s`` seconds."""
        ...


class EngineError(ValueError):
    """A request an engine cannot serve (bad clip name, impossible constraint...): a client error."""


class UnknownClipError(EngineError):
    """A clip name the database does not have (the message names the clips it has)."""


@dataclass(slots=True)
class Solution:
    """One result of a search.

    Attributes
    ----------
    motion: the synthesized motion (metres, Y up).
    score: total cost, lower is better.
    terms: the score's terms by name.
    provenance: per output frame, ``(clip name, source frame)``.
    constraint_errors: per constraint, its error measured on ``motion`` and whether it is
        satisfied (the ``quality`` report's, filled by :meth:`Engine.finish`).
    metrics: the engine's own figures (search statistics...); the quality report adds its own.
    annotations: per-frame annotations propagated to the output (e.g. contacts).
    quality: the quality report of ``motion`` (:func:`motion.quality.assess`); the runtime
        computes one (plausibility only) for engines that leave it out.
    """

    motion: Motion
    score: float
    terms: dict[str, float] = field(default_factory=dict)
    provenance: list[tuple[str, int]] = field(default_factory=list)
    constraint_errors: dict[str, Any] = field(default_factory=dict)
    metrics: dict[str, float] = field(default_factory=dict)
    annotations: dict[str, Any] = field(default_factory=dict)
    quality: QualityReport | None = None


class Emitter(Protocol):
    """What the runtime gives a running engine to report with."""

    def solution(self, solution: Solution) -> str:
        """Publish an improved solution; returns its result id."""
        ...

    def progress(self, fraction: float, message: str = "") -> None:
        """Publish progress of a long step, ``fraction`` in [0, 1]."""
        ...


class CollectingEmitter:
    """An :class:`Emitter` that keeps everything an engine reports, for running engines directly
    from Python (benchmarks, notebooks, tests) without the job runtime.

    ``solutions`` in emission order with ``times`` (seconds since the emitter was made);
    ``progress_events`` as ``(fraction, message)``; ``solution`` returns ids ``r1, r2, ...``.
    """

    def __init__(self) -> None:
        self.t0 = time.perf_counter()
        self.solutions: list[Solution] = []
        self.times: list[float] = []
        self.progress_events: list[tuple[float, str]] = []

    def solution(self, solution: Solution) -> str:
        self.solutions.append(solution)
        self.times.append(time.perf_counter() - self.t0)
        return f"r{len(self.solutions)}"

    def progress(self, fraction: float, message: str = "") -> None:
        self.progress_events.append((fraction, message))

    @property
    def messages(self) -> list[str]:
        return [message for _, message in self.progress_events]

    @property
    def latest(self) -> Solution | None:
        """The last solution emitted (an anytime engine's best so far)."""
        return self.solutions[-1] if self.solutions else None

    @property
    def best(self) -> Solution | None:
        """The lowest-scoring solution (what the runtime reports as the job's result)."""
        return min(self.solutions, key=lambda s: s.score) if self.solutions else None


RequestT = TypeVar("RequestT", bound=JobRequestBase)
SpecT = TypeVar("SpecT", bound=DatabaseSpecBase)

Role = Literal["control", "target", "leader", "follower"]
"""What a clip is in its database besides an example (a control database's pairs, a rhythm
database's couples)."""
ControlKind = Literal["motion", "path"]
"""What a control database follows: a leader's motion (pairs with controls) or a path."""


@dataclass(frozen=True, slots=True)
class DatabaseFacts:
    """What a work budget needs of a built database: its rate (fps), its joints and the frames of
    each clip at its rate, by name."""

    fps: float
    joints: int
    clip_frames: dict[str, int]
    joint_names: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class OutputEstimate:
    """The output a request asks of its engine, as far as known before running it: ``frames`` per
    character at the output rate ``fps`` (``None``: unknown until run), ``characters`` output
    motions, and the engine's peak working memory per output joint-frame (bytes).

    What the request's input files add, from their headers and capped counts only (bounded time
    and memory whatever a file holds): ``input_bytes`` the engine holds while reading them (a
    recording decoded), and ``problems``, sentences for a budget refusal (a MIDI file with
    millions of events or a 1 µs tempo)."""

    frames: int | None
    characters: int
    fps: float
    bytes_per_joint_frame: int
    input_bytes: int = 0
    problems: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class KindSummary:
    """An engine's part of a database summary: the clips' roles, what a control database follows,
    whether a rhythm database has couples, what a graph build kept."""

    roles: dict[str, Role] = field(default_factory=dict)
    control: ControlKind | None = None
    couples: bool = False
    graph: GraphKept | None = None


BYTES_PER_JOINT_FRAME = 400
"""Peak working memory per output joint-frame of an engine that does not say (the largest of the
built-in engines', measured on CMU salsa at 120 fps)."""


class Engine(ABC, Generic[RequestT, SpecT]):
    """A loaded engine: a database ready to answer requests.

    Subclasses set ``name`` (the request's ``engine``), ``kind`` (the database kind it needs),
    ``request_model`` and ``spec_model`` (their schemas, from which the registry builds the
    request and spec unions), implement :meth:`build` (the kind-specific arrays) and
    :meth:`search`, and override what else they know (:meth:`estimate`, :meth:`summarize`, the
    query API).
    """

    name: ClassVar[str]
    kind: ClassVar[str]
    request_model: ClassVar[type[JobRequestBase]]
    spec_model: ClassVar[type[DatabaseSpecBase]]
    summary_arrays: ClassVar[tuple[str, ...]] = ()
    """Arrays of a database besides the library's that :meth:`summarize` reads."""

    def __init__(self, library: MotionLibrary, arrays: Arrays) -> None:
        self.library = library
        self.arrays = arrays
        self._reference: Reference | None = None
        self._floors: dict[tuple[str, ...], dict[int, tuple[float, float]]] = {}

    @classmethod
    def load(cls, arrays: Arrays) -> Engine[RequestT, SpecT]:
        """The engine loaded from a built database's arrays (the motion library and the kind's)."""
        return cls(library_from_arrays(arrays), arrays)

    @classmethod
    def build_database(
        cls, spec: SpecT, clips: list[ClipInput], emit: Emitter, should_stop: ShouldStop
    ) -> tuple[Arrays, MotionLibrary]:
        """A database of ``spec`` built from ``clips``: its arrays (the motion library, the kind's
        :meth:`build`, the examples' quality reference and foot floor) and its library, with
        progress reported to ``emit`` by phase (:data:`BUILD_PHASES`: one overall fraction that
        only moves forward, messages ``"phase: detail"``). Raises :class:`InterruptedError` once
        ``should_stop()``."""
        progress = PhasedProgress.of(emit)
        progress.report(0.0, "reading clips", f"{len(clips)} clip{'s' if len(clips) != 1 else ''}")
        notes: list[ReadWarning] = []
        library = cls.library_for(spec, build_library(clips, spec.fps, warnings=notes))
        for note in notes:  # what a clip's file needed to be read (it was read)
            progress.progress(0.0, f"warning: clip {note.source!r}: {note.message}")
        if should_stop():
            raise InterruptedError("build cancelled")
        progress.report(
            BUILD_PHASES["library"], "motion library", f"{library.total_frames} frames at {library.fps:g} fps"
        )
        return cls.library_arrays(spec, library, progress, should_stop), library

    @classmethod
    def library_arrays(
        cls, spec: SpecT, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop
    ) -> Arrays:
        """The arrays of a database of ``spec`` on ``library`` (as :meth:`library_for` gives it):
        the library's, the kind's :meth:`build`, the examples' quality reference and foot floor
        (what :meth:`build_database` stores; the benches build libraries of their own with it).
        Raises :class:`InterruptedError` once ``should_stop()``. The kind's build reports its own
        fractions, 0 to 1, as the phase named after the kind (:data:`BUILD_PHASES`)."""
        progress = PhasedProgress.of(emit)
        extra = cls.build(
            spec,
            library,
            progress.phase(cls.name, BUILD_PHASES["library"], BUILD_PHASES["kind"]),
            should_stop,
        )
        if should_stop():
            raise InterruptedError("build cancelled")
        arrays = library_to_arrays(library)
        arrays.update(extra)
        progress.report(BUILD_PHASES["kind"], "quality reference", "measuring the examples")
        arrays.update(cls.quality_reference_of(library, arrays).to_arrays())
        arrays.update(foot_floor_arrays(library, cls.example_clips(library, arrays)))
        return arrays

    @classmethod
    def build(cls, spec: SpecT, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop) -> Arrays:
        """Kind-specific database arrays computed from the library (default: none)."""
        return {}

    @classmethod
    def library_for(cls, spec: SpecT, library: MotionLibrary) -> MotionLibrary:
        """The library a database of ``spec`` is built from and stores, given its clips as read
        (default: as read; graph and annotated databases add mirror images with ``mirror``)."""
        return library

    @classmethod
    def clip_sources(cls, stored_spec: Mapping[str, Any], stored: int) -> list[int | None]:
        """For each of the ``stored`` clips of a database of ``stored_spec`` (JSON, as stored), the
        index in the spec's ``clips`` of the clip it is or was made from (:meth:`library_for`: a
        mirror image or a time-scaled copy comes from its clip), ``None`` for none; the summary
        gives a clip its source's units. Default: the spec's clips, in order."""
        return clip_sources(len(stored_spec.get("clips") or []), 1, stored)

    @classmethod
    def library_frames(cls, spec: SpecT, frames: int) -> int:
        """Frames of the library a database of ``spec`` stores and builds on (:meth:`library_for`),
        given its clips' ``frames`` at the database rate (default: the same; ``mirror`` doubles
        them), for the service's size limits before a build."""
        return frames

    @classmethod
    def spec_problems(cls, spec: SpecT, frames: dict[str, int], fps: float) -> list[str]:
        """What the build of ``spec`` would refuse, found from its clips' lengths alone: ``frames``
        by clip name at the database rate ``fps``; one sentence each (none by default). The
        service refuses such a spec at submission (422) instead of failing its build later."""
        return []

    @classmethod
    def build_work(cls, spec: SpecT, frames: int) -> BuildWork | None:
        """Estimated CPU time and peak memory of building a database of ``frames`` frames (at its
        rate) with ``spec``; ``None`` when the engine gives no estimate (then the service's frame
        limit applies)."""
        return None

    @classmethod
    def estimate(cls, request: RequestT, facts: DatabaseFacts) -> OutputEstimate:
        """The output ``request`` asks for against a database with ``facts`` (for work budgets and
        the short-result flag). Default: ``request.frames`` when the request has an integer one,
        ``characters`` (a count or a list) times two for ``couples``, and
        :data:`BYTES_PER_JOINT_FRAME`."""
        frames = getattr(request, "frames", None)
        cast = getattr(request, "characters", 1) or 1
        characters = (len(cast) if isinstance(cast, list) else int(cast)) * (
            2 if getattr(request, "couples", False) else 1
        )
        fps = float(getattr(request, "fps", None) or facts.fps)
        return OutputEstimate(
            int(frames) if isinstance(frames, int) else None, characters, fps, BYTES_PER_JOINT_FRAME
        )

    @classmethod
    def summarize(cls, stored_spec: Mapping[str, Any], arrays: DatabaseArrays) -> KindSummary:
        """The engine's part of a database's summary, from its spec as stored (JSON, clips resolved)
        and its :attr:`summary_arrays` (default: nothing beyond the library's)."""
        return KindSummary()

    @classmethod
    def example_clips(cls, library: MotionLibrary, arrays: Arrays) -> list[int]:
        """Library clips whose motion the engine's outputs are made of (default: every clip); the
        quality report's plausibility limits come from them (a control database's targets, not
        its controls)."""
        return list(range(len(library.motions)))

    @classmethod
    def quality_reference_of(cls, library: MotionLibrary, arrays: Arrays) -> Reference:
        """What the examples do (:class:`motion.plausibility.Reference`), stored with the
        database (:meth:`Reference.to_arrays`) or measured now for databases built before."""
        stored = Reference.from_arrays(arrays)
        if stored is not None:
            return stored
        examples = []
        for i in cls.example_clips(library, arrays):
            m = library.motions[i]
            examples.append((m.global_positions() * m.metres_per_unit, m.skeleton, m.fps))
        return reference_from_positions(examples)

    @property
    def quality_reference(self) -> Reference:
        """This database's :meth:`quality_reference_of` (measured once per loaded engine)."""
        if self._reference is None:
            self._reference = self.quality_reference_of(self.library, self.arrays)
        return self._reference

    def foot_floor(self, skeleton: Skeleton) -> dict[int, tuple[float, float]]:
        """Per foot joint of ``skeleton`` (:func:`motion.contacts.foot_joints`), its height when
        planted in the examples of that skeleton (the 5th percentile over their frames) and the
        lowest it goes (0.1st percentile), metres; empty when none share it or it has no feet.
        Cached per skeleton."""
        key = skeleton.names
        got = self._floors.get(key)
        if got is None:
            stored = self.arrays.get(FLOOR_PREFIX + "names")
            if stored is not None and tuple(str(n) for n in stored) == key:
                planted = np.asarray(self.arrays[FLOOR_PREFIX + "planted"], dtype=np.float64)
                lowest = np.asarray(self.arrays[FLOOR_PREFIX + "lowest"], dtype=np.float64)
                feet = np.asarray(self.arrays[FLOOR_PREFIX + "joints"], dtype=np.intp)
                got = {int(j): (float(a), float(b)) for j, a, b in zip(feet, planted, lowest, strict=True)}
            else:
                got = foot_floor_of(self.library, self.example_clips(self.library, self.arrays), skeleton)
            self._floors[key] = got
        return got

    # -- the query API (what the service may ask of a database besides jobs) ---------------------
    @classmethod
    def check_labels(cls, database_id: str) -> None:
        """Raise :class:`EngineError` unless this kind of database carries labels
        (:meth:`clip_labels`, :meth:`corrected_spec`)."""
        raise EngineError(f"database {database_id} is {cls.kind!r}, not 'annotated'")

    @classmethod
    def clip_labels(
        cls, arrays: DatabaseArrays, clip: str, start: int = 0, end: int | None = None
    ) -> ClipLabels:
        """The labels of frames ``[start, end)`` of ``clip`` (database frames), reading only the
        arrays they need. Engines whose databases carry labels override it; raises
        :class:`EngineError` (unknown clip, empty range, no labels)."""
        raise EngineError(f"{cls.kind!r} databases carry no labels; 'annotated' databases do")

    @classmethod
    def corrected_spec(
        cls, spec: DatabaseSpecBase, corrections: Sequence[LabelCorrection], arrays: DatabaseArrays | None
    ) -> DatabaseSpecBase:
        """The spec of the database with corrected labels (build it to retrain); ``arrays`` of the
        built database, needed when a correction accepts its propagated labels. Raises
        :class:`EngineError`."""
        raise EngineError(f"{cls.kind!r} databases carry no labels to correct; 'annotated' databases do")

    @classmethod
    def check_movement_graph(cls, database_id: str) -> None:
        """Raise :class:`EngineError` unless this kind of database has a movement graph (checked
        before its arrays are read)."""
        raise EngineError(
            f"database {database_id} is {cls.kind!r}: only 'rhythm' databases have a movement graph"
        )

    @classmethod
    def movement_graph(
        cls,
        arrays: DatabaseArrays,
        database_id: str,
        stored_spec: Mapping[str, Any],
        derived_from: DerivedFrom | None = None,
    ) -> MovementGraph:
        """The database's movement graph (its groups of movements and the transitions between
        them); raises :class:`EngineError` for databases without one."""
        cls.check_movement_graph(database_id)
        raise NotImplementedError(f"{cls.__name__} has a movement graph but does not describe it")

    @classmethod
    def recording_beats(cls, data: bytes, tempo_bpm: float | None = None) -> dict[str, Any]:
        """``{"duration_s", "tempo_bpm", "tempo_confidence", "beats_s", "downbeat_s"}`` of a music
        recording's bytes (seconds), for engines that dance to music; raises :class:`EngineError`
        (unreadable, silent, too long, no beat; or an engine that reads no music)."""
        raise EngineError(f"engine {cls.name!r} reads no music recordings; the 'rhythm' engine does")

    @classmethod
    def edit_movement_graph(
        cls, arrays: DatabaseArrays, edits: GraphEdits, database_id: str
    ) -> tuple[list[ResolvedEdit], Arrays]:
        """The edits resolved (groups to ids, weights explicit) and the arrays of the database
        derived by them; raises :class:`EngineError` naming a broken rule, or for databases
        without a movement graph."""
        cls.check_movement_graph(database_id)
        raise NotImplementedError(f"{cls.__name__} has a movement graph but does not edit it")

    @classmethod
    def check_live_session(cls, database_id: str) -> None:
        """Raise :class:`EngineError` unless this kind of database dances live
        (:meth:`live_session`; checked before the database is loaded)."""
        raise EngineError(f"database {database_id} is {cls.kind!r}: only 'rhythm' databases dance live")

    @classmethod
    def check_live_control(cls, database_id: str) -> None:
        """Raise :class:`EngineError` unless this kind of database follows a live control
        (:meth:`live_control`; checked before the database is loaded)."""
        raise EngineError(f"database {database_id} is {cls.kind!r}: only 'control' databases follow live")

    def live_session(self, *, seed: int = 0, fps: float | None = None, accent: float = 0.6) -> LiveSession:
        """A character driven live by events (``seed`` of its random choices, output ``fps``,
        beat ``accent``); raises :class:`EngineError` for engines without live sessions."""
        raise EngineError(f"engine {self.name!r} has no live sessions; the 'rhythm' engine has")

    def live_control(self, **settings: Any) -> LiveControlSession:
        """A target generated from a control streamed live (``settings``: the engine's session
        options); raises :class:`EngineError` for engines without live control."""
        raise EngineError(f"engine {self.name!r} has no live control sessions; the 'control' engine has")

    def finish(
        self, solution: Solution, inputs: QualityInputs | None = None, positions: Array | None = None
    ) -> Solution:
        """``solution`` with its quality report against this database's examples
        (:func:`finish_solution`; ``positions``: the motion's global joint positions ``(F, J, 3)``
        when the engine has them)."""
        return finish_solution(solution, inputs, self.quality_reference, positions)

    @abstractmethod
    def search(self, request: RequestT, run: Run) -> Stopped:
        """Answer a request, calling ``run.emit.solution`` for every improvement, until the work
        the request asks for is done or ``run`` says to stop (its time cap, a cancel); returns
        why it stopped."""


AnyEngine: TypeAlias = Engine[Any, Any]
"""A loaded engine, whatever its request and spec models (what the runtime holds)."""


FLOOR_PREFIX = "quality.floor."
"""Arrays of the examples' foot floor heights stored with a database (:func:`foot_floor_arrays`)."""


def foot_floor_of(
    library: MotionLibrary, examples: list[int], skeleton: Skeleton
) -> dict[int, tuple[float, float]]:
    """:meth:`Engine.foot_floor` measured on the ``examples`` clips of ``library`` that share
    ``skeleton``."""
    from motion.contacts import foot_joints

    same = [library.motions[i] for i in examples if library.motions[i].skeleton.names == skeleton.names]
    try:
        feet = foot_joints(skeleton)
    except MotionError:
        return {}
    if not same or not feet.size:
        return {}
    heights = np.concatenate([m.global_positions()[:, feet, 1] * m.metres_per_unit for m in same])
    planted, lowest = np.percentile(heights, [5, 0.1], axis=0)
    return {int(j): (float(a), float(b)) for j, a, b in zip(feet, planted, lowest, strict=True)}


def foot_floor_arrays(library: MotionLibrary, examples: list[int]) -> Arrays:
    """The foot floor heights of the first example's skeleton, as npz-ready arrays (stored at
    build so that the first request does not measure them)."""
    if not examples:
        return {}
    skeleton = library.motions[examples[0]].skeleton
    floor = foot_floor_of(library, examples, skeleton)
    if not floor:
        return {}
    joints = sorted(floor)
    return {
        FLOOR_PREFIX + "names": np.array(skeleton.names, dtype=str),
        FLOOR_PREFIX + "joints": np.array(joints, dtype=np.int64),
        FLOOR_PREFIX + "planted": np.array([floor[j][0] for j in joints]),
        FLOOR_PREFIX + "lowest": np.array([floor[j][1] for j in joints]),
    }


def finish_solution(
    solution: Solution,
    inputs: QualityInputs | None,
    reference: Reference | None,
    positions: Array | None = None,
) -> Solution:
    """``solution`` with its quality report: :func:`motion.quality.assess` of its motion against
    the request's goals (``inputs``) and the database's examples (``reference``); ``positions``:
    the motion's global joint positions ``(F, J, 3)`` in its units when the caller has them."""
    report = assess(solution.motion, inputs, reference, positions)
    solution.quality = report
    solution.constraint_errors = report.constraint_errors
    return solution
