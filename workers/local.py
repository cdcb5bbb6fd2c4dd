"""Jobs run in the calling process, on files: what ``segue build`` and ``segue synth`` do.

The same code paths as the service (:func:`workers.execute.build_database_bytes` and
:func:`workers.execute.run_search`), with a database *directory* instead of the store:

``DIR/spec.json``
    the spec as given, clip paths resolved (plus each clip's sha256);
``DIR/info.json``
    :class:`schemas.DatabaseInfo` (the id is the same content address the service computes);
``DIR/data.npz``
    the database arrays (``allow_pickle=False``).
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from engines.base import ClipInput
from engines.registry import parse_database_spec
from motion import Motion, MotionError
from motion.export.events import result_events, sorted_events
from motion.io import save_motion
from motion.samples import declared_units, resolve_path
from schemas import DatabaseInfo, DatabaseStatus, EventType, JobEvent, Report
from schemas.bases import DatabaseSpecBase
from schemas.databases import database_id

from .execute import JobFailure, build_database_bytes, run_search
from .prepare import PrepareError, parse, prepare_in_dir
from .store import load_npz, now

Publish = Callable[[EventType, dict[str, Any]], None]


class EventWriter:
    """Numbers events and writes them as JSON lines (and optionally echoes progress)."""

    def __init__(
        self, job_id: str, sink: TextIO | None = None, echo: Callable[[JobEvent], None] | None = None
    ):
        self.job_id, self.sink, self.echo = job_id, sink, echo
        self.count = 0
        self.attempt = 0
        """The run publishing (1 from its ``started`` on: a local job runs once), as in the service."""
        self.events: list[JobEvent] = []

    def __call__(self, type_: EventType, data: dict[str, Any]) -> None:
        self.count += 1
        if type_ == EventType.started:
            self.attempt += 1
        event = JobEvent(
            id=self.count, job=self.job_id, type=type_, time=time.time(), data=data, attempt=self.attempt
        )
        self.events.append(event)
        if self.sink is not None:
            self.sink.write(event.model_dump_json() + "\n")
            self.sink.flush()
        if self.echo is not None:
            self.echo(event)


def load_spec_file(path: Path) -> tuple[DatabaseSpecBase, list[ClipInput], list[str]]:
    """A spec file and its clips (paths relative to the spec file, or ``sample:NAME``), with each
    clip's sha256."""
    spec = parse_database_spec(path.read_bytes())
    clips, digests = [], []
    for source in spec.clips:
        if source.bvh is None:
            raise JobFailure("invalid_request", 'in a spec file, clips are given as {"bvh": "path"}')
        try:
            data = resolve_path(source.bvh, path.parent).read_bytes()
        except MotionError as exc:
            raise JobFailure("invalid_request", f"clip {source.bvh!r}: {exc}") from None
        except OSError as exc:
            raise JobFailure("invalid_request", f"clip {source.bvh!r}: {exc.strerror or exc}") from None
        digests.append(hashlib.sha256(data).hexdigest())
        clips.append(
            ClipInput(
                source.display_name(),
                data,
                source.units if source.units is not None else declared_units(source.bvh),
                [lb.model_dump() for lb in source.labels],
                source.animation,
            )
        )
    return spec, clips, digests


def build_to_dir(spec_path: Path, out_dir: Path, publish: Publish) -> DatabaseInfo:
    """Build the database of a spec file into ``out_dir`` (created; existing files replaced)."""
    publish(EventType.started, {})
    spec, clips, digests = load_spec_file(spec_path)
    data, library = build_database_bytes(spec, clips, publish, lambda: False)
    out_dir.mkdir(parents=True, exist_ok=True)
    resolved = spec.model_dump(mode="json")
    for entry, digest in zip(resolved["clips"], digests, strict=True):
        entry["sha256"] = digest
    info = DatabaseInfo(
        id=database_id(spec, digests),
        kind=spec.kind,
        name=spec.name,
        status=DatabaseStatus.ready,
        clips=list(library.names),
        frames=library.total_frames,
        fps=library.fps,
        created_at=now(),
    )
    (out_dir / "data.npz").write_bytes(data)
    (out_dir / "spec.json").write_text(json.dumps(resolved, indent=2), encoding="utf-8")
    (out_dir / "info.json").write_text(info.model_dump_json(indent=2), encoding="utf-8")
    publish(EventType.done, {"result": None, "database": info.id})
    return info


def synth_from_dir(
    request_path: Path,
    db_dir: Path,
    publish: Publish,
    budget_s: float | None = None,
    feet: str | None = None,
) -> tuple[Motion, Report] | None:
    """Run a request file against a database directory; returns the best motion and its report
    (``None`` if the engine found nothing, after a ``failed`` event). ``budget_s`` and ``feet``
    override the request's (the CLI's ``--budget`` and ``--feet``)."""
    publish(EventType.started, {})
    request = parse(json.loads(request_path.read_bytes()))
    if budget_s is not None:
        request = request.with_budget(budget_s)
    if feet is not None:
        if "feet" not in type(request).model_fields:
            raise JobFailure(
                "invalid_request",
                f"the {request.engine!r} engine has no foot clean-up: --feet does not apply",
            )
        copy = request.model_copy()
        request.__pydantic_validator__.validate_assignment(copy, "feet", feet)
        request = copy
    try:
        prepared = prepare_in_dir(request, request_path.resolve().parent, db_dir)
        arrays = load_npz((db_dir / "data.npz").read_bytes())
    except PrepareError as exc:
        raise JobFailure(exc.code, exc.message) from None
    except OSError as exc:
        raise JobFailure(
            "invalid_request", f"{db_dir} is not a database directory ({exc.strerror or exc})"
        ) from None
    engine = prepared.engine.load(arrays)
    request = prepared.request
    results: dict[str, tuple[Motion, Report]] = {}

    def save(rid: str, motion: Motion, report: Report) -> None:
        results[rid] = (motion, report)

    best: list[str | None] = [None]

    def track(type_: EventType, data: dict[str, Any]) -> None:
        if type_ in (EventType.done, EventType.cancelled):
            best[0] = data.get("result")
        publish(type_, data)

    try:
        run_search(engine, request, "local", track, lambda: False, save)
    except JobFailure as exc:
        publish(EventType.failed, {"error": {"code": exc.code, "message": exc.message}})
        return None
    return results[best[0]] if best[0] is not None else None


def write_result(motion: Motion, report: Report, out: Path, report_path: Path | None) -> list[str]:
    """Write the motion by extension (and the report as JSON); returns notes for the user.

    A ``.glb`` or ``.json`` output carries the result's music beats and labels (from the report's
    annotations) as events (:mod:`motion.export.events`), when it has any."""
    events: list[dict[str, Any]] = []
    if out.name.lower().endswith((".glb", ".json")):
        events = result_events(report.annotations, motion.fps, motion.duration_s)
    notes = save_motion(motion, out, extra_events=sorted_events(events))
    if report_path is not None:
        report_path.write_text(report.model_dump_json(indent=2), encoding="utf-8")
    return notes
