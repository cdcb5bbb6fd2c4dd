"""Running one job: a database build or a synthesis, reporting through events.

:func:`execute_job` is what every backend runs in a worker process. It only publishes events
(``started``, ``progress``, ``solution``, then exactly one of ``done``/``failed``/``cancelled``) and
writes files through the :class:`~workers.store.Store`; job status is a fold over those events
(:func:`apply_event`), so every backend derives it the same way.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

from pydantic import ValidationError

from engines.base import AnyEngine, ClipInput, EngineError, MotionLibrary, Run, Solution, Stopped
from engines.registry import UnavailableError, kind_class, parse_database_spec
from motion import Motion, MotionError
from motion.plausibility import Reference
from motion.quality import assess
from schemas import DatabaseStatus, EventType, JobInfo, JobStatus, ProvenanceEntry, Report
from schemas.bases import DatabaseSpecBase, JobRequestBase

from .dbcache import CacheFull
from .engine_cache import EngineCache as EngineCache  # re-exported: where it lived before
from .engine_cache import OpenArrays
from .prepare import PrepareError, prepare
from .storage_errors import storage_problem
from .store import NotFoundError, Store, now, npz_bytes

log = logging.getLogger("segue.worker")

Publish = Callable[[EventType, dict[str, Any]], None]
ShouldStop = Callable[[], bool]
OnLoad = Callable[[bool], None]
"""``on_load(True)`` before a job loads its database, ``on_load(False)`` after (the supervisor times
the load apart from the job's budget)."""


class JobFailure(Exception):
    """A job that cannot complete, with an error code for the ``failed`` event."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


SaveResult = Callable[[str, Motion, Report], None]


class SolutionRecorder:
    """The engine-facing side of a job (an ``engines.base.Emitter``): turns each solution into a
    result (motion + :class:`~schemas.Report`, saved through ``save``) and an event.

    A result that beats every earlier one is a ``solution`` event (so their scores strictly
    decrease); any other (an alternative the engine offers) is an ``alternative`` event. Every
    report carries the quality report of its motion (:func:`motion.quality.assess`): the engine's
    own, or one measured here against ``reference`` for engines that give none."""

    def __init__(
        self,
        job_id: str,
        engine: str,
        publish: Publish,
        save: SaveResult,
        attempt: int = 1,
        reference: Reference | None = None,
    ) -> None:
        self.job_id, self.engine, self.publish, self.save = job_id, engine, publish, save
        self.reference = reference
        # a re-run after a lost worker numbers its results apart, so earlier events stay valid
        self.prefix = "r" if attempt <= 1 else f"a{attempt}r"
        self.t0 = time.perf_counter()
        self.count = 0
        self.best: tuple[float, str] | None = None
        self.best_saved: tuple[Motion, Report] | None = None
        self.verdicts: dict[str, tuple[bool | None, list[str]]] = {}

    def solution(self, solution: Solution) -> str:
        self.count += 1
        rid = f"{self.prefix}{self.count}"
        motion = solution.motion
        quality = solution.quality or assess(motion, None, self.reference)
        metrics = {**quality.metrics, **solution.metrics}
        report = Report(
            job=self.job_id,
            result=rid,
            engine=self.engine,
            ok=quality.ok,
            reasons=quality.reasons,
            score=float(solution.score),
            terms={k: float(v) for k, v in solution.terms.items()},
            constraint_errors=quality.constraint_errors,
            plausibility=quality.plausibility,
            metrics={k: float(v) for k, v in metrics.items()},
            frames=motion.num_frames,
            fps=motion.fps,
            provenance=[ProvenanceEntry(clip=c, frame=int(f)) for c, f in solution.provenance],
            annotations=solution.annotations,
        )
        self.save(rid, motion, report)
        self.verdicts[rid] = (quality.ok, quality.reasons)
        improved = self.best is None or solution.score < self.best[0]
        if improved:
            self.best = (float(solution.score), rid)
            self.best_saved = (motion, report)
        elapsed_ms = (time.perf_counter() - self.t0) * 1e3
        self.publish(
            EventType.solution if improved else EventType.alternative,
            {
                "score": float(solution.score),
                "terms": report.terms,
                "elapsed_ms": round(elapsed_ms, 1),
                "result": rid,
                "ok": quality.ok,
                "reasons": quality.reasons,
                "frames": motion.num_frames,
                "fps": motion.fps,
            },
        )
        return rid

    def progress(self, fraction: float, message: str = "") -> None:
        self.publish(
            EventType.progress, {"fraction": float(min(max(fraction, 0.0), 1.0)), "message": message}
        )

    @property
    def best_result(self) -> str | None:
        return None if self.best is None else self.best[1]

    def conclude(self, stopped: Stopped) -> dict[str, Any]:
        """Record why the search stopped in the best result's report (saved again) and return
        the terminal event's ``{"stopped", "stopped_reason"}``."""
        fields = {"stopped": stopped.value, "stopped_reason": stopped.reason}
        if self.best_saved is not None and self.best is not None:
            motion, report = self.best_saved
            self.save(self.best[1], motion, report.model_copy(update=fields))
        return fields

    def verdict(self, rid: str | None) -> dict[str, Any]:
        """``{"ok", "reasons"}`` of a result, for the terminal event."""
        if rid is None or rid not in self.verdicts:
            return {}
        ok, reasons = self.verdicts[rid]
        return {"ok": ok, "reasons": reasons}


def execute_job(
    store: Store,
    job_id: str,
    kind: str,
    payload: dict[str, Any],
    publish: Publish,
    should_stop: ShouldStop,
    cache: EngineCache,
    attempt: int = 1,
    *,
    open_arrays: OpenArrays | None = None,
    on_load: OnLoad | None = None,
) -> None:
    """Run a job to its terminal event (never raises for job-level problems; raises
    :class:`~workers.dbcache.CacheFull` when this host cannot cache the job's database, which is
    not the job's fault: the caller gives it to another worker).

    Parameters
    ----------
    kind:
        ``"build"`` (payload ``{"database": id}``), ``"synth"`` (payload ``{"request": {...}}``) or
        ``"task"`` (a small job for an API request: :mod:`workers.tasks`).
    publish:
        Called with each event type and data, in order.
    should_stop:
        True once the job is cancelled (polled by the engine).
    open_arrays:
        A database's arrays by id (default: the store's, memory-mapped from its local copy).
    on_load:
        Told when loading the database starts (True) and ends (False).
    """
    load = open_arrays or store.database_arrays
    publish(EventType.started, {})
    try:
        if kind == "build":
            _build(store, payload["database"], publish, should_stop)
        elif kind == "synth":
            _synth(store, job_id, payload["request"], publish, should_stop, cache, load, attempt, on_load)
        elif kind == "task":  # a small job for an API request (workers.tasks)
            from .tasks import run_task

            run_task(store, payload["request"], publish)
        else:
            raise JobFailure("invalid_job", f"unknown job kind {kind!r}")
    except JobFailure as exc:
        publish(EventType.failed, {"error": {"code": exc.code, "message": exc.message}})
    except (EngineError, MotionError, UnavailableError, NotFoundError, ValidationError) as exc:
        publish(EventType.failed, {"error": {"code": "invalid_request", "message": str(exc)}})
    except CacheFull:
        raise  # this host's problem, not the job's: its owner gives the job to another worker
    except Exception as exc:  # a storage failure names itself; anything else is a bug: report it
        problem = storage_problem(exc)
        if problem is not None:  # full, read-only or unreachable store (the API's 507 codes)
            log.warning("job %s: %s", job_id, problem[1])
            publish(EventType.failed, {"error": {"code": problem[0], "message": problem[1]}})
            return
        log.exception("job %s crashed", job_id)
        publish(EventType.failed, {"error": {"code": "internal", "message": f"{type(exc).__name__}: {exc}"}})


def build_database_bytes(
    spec: DatabaseSpecBase, clips: list[ClipInput], publish: Publish, should_stop: ShouldStop
) -> tuple[bytes, MotionLibrary]:
    """:func:`build_database_arrays` as the bytes of one ``.npz`` (``segue build``'s folders)."""
    arrays, library = build_database_arrays(spec, clips, publish, should_stop)
    return npz_bytes(arrays), library


def build_database_arrays(
    spec: DatabaseSpecBase, clips: list[ClipInput], publish: Publish, should_stop: ShouldStop
) -> tuple[dict[str, Any], MotionLibrary]:
    """The arrays of a database (:meth:`engines.base.Engine.build_database`), with progress
    events. Raises :class:`JobFailure` with code ``cancelled`` when stopped."""
    engine_cls = kind_class(spec.kind)
    recorder = SolutionRecorder("build", engine_cls.name, publish, lambda *_: None)
    try:
        arrays, library = engine_cls.build_database(spec, clips, recorder, should_stop)
    except InterruptedError:
        raise JobFailure("cancelled", "build cancelled") from None
    return arrays, library


def _build(
    store: Store,
    db_id: str,
    publish: Publish,
    should_stop: ShouldStop,
) -> None:
    """Build a database and write its arrays and its ``ready`` record. A build that fails or is
    cancelled writes no record: its terminal event does, through whoever publishes it
    (:func:`workers.records.settle_database`), so the record's reason is the one the runtime
    decided, and an engine process whose worker died (its events going nowhere) cannot leave a
    ``failed`` of its own."""
    info = store.database_info(db_id)
    spec = parse_database_spec(store.database_spec(db_id))
    kind_class(spec.kind)
    store.put_database_info(info.model_copy(update={"status": DatabaseStatus.building}))
    clips = []
    for source in spec.clips:
        if source.clip is None:
            raise JobFailure(
                "invalid_request", f"clip {source.display_name()!r} was not resolved to an upload"
            )
        labels = [lb.model_dump() for lb in source.labels]
        # the spec's unit, else the clip's own (declared at upload, e.g. a bundled sample's, or guessed)
        units = source.units if source.units is not None else store.clip_info(source.clip).units
        clips.append(
            ClipInput(source.display_name(), store.clip_bytes(source.clip), units, labels, source.animation)
        )
    try:
        arrays, library = build_database_arrays(spec, clips, publish, should_stop)
    except JobFailure as exc:
        if exc.code == "cancelled":
            publish(EventType.cancelled, {"result": None})
            return
        raise
    store.put_database_arrays(db_id, arrays)
    store.put_database_info(
        info.model_copy(
            update={
                "status": DatabaseStatus.ready,
                "frames": library.total_frames,
                "fps": library.fps,
                "error": None,
            }
        )
    )
    publish(EventType.progress, {"fraction": 1.0, "message": "built"})
    publish(EventType.done, {"result": None, "database": db_id})


def run_search(
    engine: AnyEngine,
    request: JobRequestBase,
    job_id: str,
    publish: Publish,
    should_stop: ShouldStop,
    save: SaveResult,
    attempt: int = 1,
) -> None:
    """Run an engine's search and publish the terminal event (``done`` or ``cancelled`` with the
    best result and why the search stopped: ``stopped`` ``work``, ``budget`` or ``cancelled`` and
    a ``stopped_reason`` line, also written into the best result's report); raises
    :class:`JobFailure` when it found nothing."""
    recorder = SolutionRecorder(job_id, engine.name, publish, save, attempt, engine.quality_reference)
    stopped = engine.search(request, Run(request.budget_s, should_stop, recorder)) or Stopped.work
    if should_stop():
        stopped = Stopped.cancelled
    best = recorder.best_result
    if best is None:
        if stopped is Stopped.cancelled:
            publish(EventType.cancelled, {"result": None, "stopped": stopped.value})
            return
        raise JobFailure("no_solution", "the engine found no solution within the budget")
    fields = recorder.conclude(stopped)
    event = EventType.cancelled if stopped is Stopped.cancelled else EventType.done
    publish(event, {"result": best, **recorder.verdict(best), **fields})


def _synth(
    store: Store,
    job_id: str,
    request_data: dict[str, Any],
    publish: Publish,
    should_stop: ShouldStop,
    cache: EngineCache,
    load: OpenArrays,
    attempt: int = 1,
    on_load: OnLoad | None = None,
) -> None:
    try:
        prepared = prepare(request_data, store)
    except PrepareError as exc:
        raise JobFailure(exc.code, exc.message) from None
    if on_load is not None:
        on_load(True)
    try:
        engine = cache.get(prepared.database.id, prepared.engine, load)
    finally:
        if on_load is not None:
            on_load(False)

    def save(rid: str, motion: Motion, report: Report) -> None:
        store.put_result(job_id, rid, motion, report)

    run_search(engine, prepared.request, job_id, publish, should_stop, save, attempt)


def apply_event(info: JobInfo, event_type: EventType, data: dict[str, Any], event_id: int) -> JobInfo:
    """The job status after an event (status is a fold over the job's events)."""
    update: dict[str, Any] = {"last_event": event_id}
    if event_type == EventType.started:
        update.update(status=JobStatus.running, started_at=now())
        if isinstance(data.get("attempt"), int):
            update["attempt"] = data["attempt"]
    elif event_type == EventType.solution:
        update["result"] = data.get("result")
    elif event_type in (EventType.done, EventType.cancelled):
        update.update(
            status=JobStatus.done if event_type == EventType.done else JobStatus.cancelled,
            finished_at=now(),
            result=data.get("result") or info.result,
        )
    elif event_type == EventType.failed:
        update.update(status=JobStatus.failed, finished_at=now(), error=data.get("error", {}).get("message"))
    return info.model_copy(update=update)
