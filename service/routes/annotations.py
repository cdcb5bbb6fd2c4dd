"""``/v1/databases/{id}/labels`` and ``/corrections``: the annotation engine's correction loop.

The user looks at a clip's labels (the user's and the SVMs' propagated ones), then accepts or
corrects label ranges; the corrected ranges are written into a new spec
(:meth:`engines.base.Engine.corrected_spec`) whose build retrains the SVMs. The answer is that new
database (202 with its ``build_job``, or 200 when a database with the same content address exists),
exactly as ``POST /v1/databases``.

Both read only the database's label table (clip names, lengths, vocabulary, per-frame labels) from
its ``data.npz``, in a worker thread, through the engine query API
(:func:`engines.base.open_database`): the motion and the search tables stay on disk.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Query, Response, status
from pydantic import Field, TypeAdapter
from starlette.concurrency import run_in_threadpool

from engines.base import EngineError, UnknownClipError
from engines.registry import kind_class, parse_database_spec
from schemas import DatabaseInfo, DatabaseStatus
from schemas.annotations import ClipLabels, LabelCorrection
from schemas.bases import DatabaseSpecBase
from workers.store import Store

from ..deps import BackendDep, JobQuotaDep, MetricsDep, PrincipalDep, SettingsDep, StoreDep
from ..errors import ApiError, conflict, responses
from ..jsonbody import json_body, json_body_doc
from ..owners import database_for
from .databases import create_from_spec

router = APIRouter(prefix="/v1/databases", tags=["databases"])

Corrections = Annotated[list[LabelCorrection], Field(min_length=1, max_length=10_000)]
CORRECTIONS_ADAPTER: TypeAdapter[list[LabelCorrection]] = TypeAdapter(Corrections)
CORRECTIONS_BODY = json_body_doc(
    "LabelCorrections", "Label corrections: 1 to 10,000 ranges to set or accept."
)
CorrectionsBody = Annotated[list[LabelCorrection], Depends(json_body(CORRECTIONS_ADAPTER.validate_python))]


def _annotated(info: DatabaseInfo, ready: bool) -> None:
    """422 unless the database carries labels; 409 unless it is built when ``ready`` is asked."""
    try:
        kind_class(info.kind).check_labels(info.id)
    except EngineError as exc:
        raise ApiError(422, "invalid_request", str(exc)) from None
    if ready and info.status != DatabaseStatus.ready:
        raise conflict("database_not_ready", f"database {info.id} is {info.status.value}")


def _corrected_spec(store: Store, info: DatabaseInfo, corrections: list[LabelCorrection]) -> DatabaseSpecBase:
    """The corrected spec (reads the label table only when a correction accepts labels)."""
    engine = kind_class(info.kind)
    spec = parse_database_spec(store.database_spec(info.id))
    if not any(c.action == "accept" for c in corrections):
        return engine.corrected_spec(spec, corrections, None)
    with store.open_database(info.id) as arrays:
        return engine.corrected_spec(spec, corrections, arrays)


def _clip_labels(store: Store, info: DatabaseInfo, clip: str, start: int, end: int | None) -> ClipLabels:
    with store.open_database(info.id) as arrays:
        return kind_class(info.kind).clip_labels(arrays, clip, start, end)


@router.post(
    "/{db_id}/corrections",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=DatabaseInfo,
    openapi_extra=CORRECTIONS_BODY,
    responses=responses(
        400,
        401,
        404,
        409,
        413,
        415,
        422,
        429,
        503,
        extra={200: {"model": DatabaseInfo, "description": "the corrected database exists"}},
    ),
)
async def correct_labels(
    db_id: str,
    response: Response,
    store: StoreDep,
    backend: BackendDep,
    metrics: MetricsDep,
    settings: SettingsDep,
    quota: JobQuotaDep,
    principal: PrincipalDep,
    corrections: CorrectionsBody,
) -> DatabaseInfo:
    """Build the database with corrected labels (``set`` a label on a clip's frame range, or
    ``accept`` the propagated labels of a range); clips are named as in the database. The build
    counts against your unfinished jobs (429 ``too_many_jobs`` over ``SEGUE_MAX_QUEUED_JOBS``)."""
    info = await run_in_threadpool(database_for, store, principal, db_id)
    quota.check(principal.name)
    _annotated(info, ready=any(c.action == "accept" for c in corrections))
    try:
        corrected = await run_in_threadpool(_corrected_spec, store, info, corrections)
    except EngineError as exc:
        raise ApiError(422, "invalid_request", str(exc)) from None
    shared = frozenset(c.clip for c in corrected.clips if c.clip is not None)
    built = await create_from_spec(
        corrected, response, store, backend, metrics, principal, shared, settings.max_database_frames
    )
    if built.build_job and response.status_code != status.HTTP_200_OK:  # a build was queued (202)
        quota.add(principal.name, built.build_job)
    return built


@router.get("/{db_id}/labels", response_model=ClipLabels, responses=responses(401, 404, 409, 422))
async def clip_labels(
    db_id: str,
    store: StoreDep,
    principal: PrincipalDep,
    clip: Annotated[str, Query(min_length=1, description="clip as named in the database")],
    start: Annotated[int, Query(ge=0)] = 0,
    end: Annotated[int | None, Query(gt=0)] = None,
) -> ClipLabels:
    """The labels of a clip of a ready ``annotated`` database as ranges (database frames): the user's
    where given, the SVMs' propagated labels elsewhere; what a client shows before it accepts or
    corrects them (``POST /v1/databases/{id}/corrections``)."""
    info = await run_in_threadpool(database_for, store, principal, db_id)
    _annotated(info, ready=True)
    try:
        return await run_in_threadpool(_clip_labels, store, info, clip, start, end)
    except UnknownClipError as exc:
        raise ApiError(404, "not_found", str(exc)) from None
    except EngineError as exc:
        raise ApiError(422, "invalid_request", str(exc)) from None
