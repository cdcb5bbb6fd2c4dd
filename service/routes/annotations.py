"""``/v1/databases/{id}/corrections``: the annotation engine's correction loop.

The user accepts or corrects label ranges of an ``annotated`` database's clips; the corrected
ranges are written into a new spec (:func:`engines.annotations.corrections.apply_corrections`)
whose build retrains the SVMs. The answer is that new database (202 with its ``build_job``, or
200 when a database with the same content address exists), exactly as ``POST /v1/databases``.
"""

from __future__ import annotations

import asyncio
from typing import Annotated

from fastapi import APIRouter, Query, Request, Response, status
from pydantic import Field, TypeAdapter

from engines.annotations.corrections import apply_corrections, propagated_ranges
from engines.annotations.search import Database
from engines.base import EngineError
from engines.library import library_from_arrays
from schemas import DatabaseInfo, DatabaseStatus
from schemas.annotations import AnnotatedDatabaseSpec, LabelCorrection
from workers.store import Store, load_npz

from ..deps import BackendDep, MetricsDep, PrincipalDep, SettingsDep, StoreDep
from ..errors import ApiError, conflict, responses
from ..jsonbody import json_body_doc, read_json, validate_off_loop
from ..owners import database_for
from .databases import create_from_spec

router = APIRouter(prefix="/v1/databases", tags=["databases"])

Corrections = Annotated[list[LabelCorrection], Field(min_length=1, max_length=10_000)]
CORRECTIONS_ADAPTER: TypeAdapter[list[LabelCorrection]] = TypeAdapter(Corrections)
CORRECTIONS_BODY = json_body_doc(
    "LabelCorrections", "Label corrections: 1 to 10,000 ranges to set or accept."
)


def _load(store: Store, db_id: str) -> Database:
    arrays = load_npz(store.database_arrays_bytes(db_id))
    return Database.from_arrays(library_from_arrays(arrays), arrays)


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
        503,
        extra={200: {"model": DatabaseInfo, "description": "the corrected database exists"}},
    ),
)
async def correct_labels(
    db_id: str,
    request: Request,
    response: Response,
    store: StoreDep,
    backend: BackendDep,
    metrics: MetricsDep,
    settings: SettingsDep,
    principal: PrincipalDep,
) -> DatabaseInfo:
    """Build the database with corrected labels (``set`` a label on a clip's frame range, or
    ``accept`` the propagated labels of a range); clips are named as in the database."""
    info = database_for(store, principal, db_id)
    body = await read_json(request, settings)
    corrections: list[LabelCorrection] = await validate_off_loop(CORRECTIONS_ADAPTER, body, request, settings)
    if info.kind != "annotated":
        raise ApiError(422, "invalid_request", f"database {db_id} is {info.kind!r}, not 'annotated'")
    spec = AnnotatedDatabaseSpec.model_validate(store.database_spec(db_id))
    db = None
    if any(c.action == "accept" for c in corrections):
        if info.status != DatabaseStatus.ready:
            raise conflict("database_not_ready", f"database {db_id} is {info.status.value}")
        db = await asyncio.to_thread(_load, store, db_id)
    try:
        corrected = apply_corrections(spec, corrections, db)
    except EngineError as exc:
        raise ApiError(422, "invalid_request", str(exc)) from None
    shared = frozenset(c.clip for c in spec.clips if c.clip is not None)
    return await create_from_spec(
        corrected, response, store, backend, metrics, principal, shared, settings.max_database_frames
    )


@router.get("/{db_id}/labels", responses=responses(401, 404, 409, 422))
async def clip_labels(
    db_id: str,
    store: StoreDep,
    principal: PrincipalDep,
    clip: Annotated[str, Query(min_length=1, description="clip as named in the database")],
    start: Annotated[int, Query(ge=0)] = 0,
    end: Annotated[int | None, Query(gt=0)] = None,
) -> dict[str, object]:
    """The labels of a clip of a ready ``annotated`` database as ranges (database frames): the user's
    where given, the SVMs' propagated labels elsewhere; what a client shows before it accepts or
    corrects them (``POST /v1/databases/{id}/corrections``)."""
    info = database_for(store, principal, db_id)
    if info.kind != "annotated":
        raise ApiError(422, "invalid_request", f"database {db_id} is {info.kind!r}, not 'annotated'")
    if info.status != DatabaseStatus.ready:
        raise conflict("database_not_ready", f"database {db_id} is {info.status.value}")
    db = await asyncio.to_thread(_load, store, db_id)
    try:
        g0 = db.frame_of(clip, 0)
    except EngineError as exc:
        raise ApiError(404, "not_found", str(exc)) from None
    try:
        ranges = propagated_ranges(db, clip, start, end)
    except EngineError as exc:
        raise ApiError(422, "invalid_request", str(exc)) from None
    return {"clip": clip, "frames": int(db.counts[int(db.clip_of[g0])]), "labels": ranges}
