"""``/v1/databases/{id}/corrections``: the annotation engine's correction loop.

The user accepts or corrects label ranges of an ``annotated`` database's clips; the corrected
ranges are written into a new spec (:func:`engines.annotations.corrections.apply_corrections`)
whose build retrains the SVMs. The answer is that new database (202 with its ``build_job``, or
200 when a database with the same content address exists), exactly as ``POST /v1/databases``.
"""

from __future__ import annotations

import asyncio
from typing import Annotated

from fastapi import APIRouter, Body, Query, Response, status

from engines.annotations.corrections import apply_corrections, propagated_ranges
from engines.annotations.search import Database
from engines.base import EngineError
from engines.library import library_from_arrays
from schemas import DatabaseInfo, DatabaseStatus
from schemas.annotations import AnnotatedDatabaseSpec, LabelCorrection
from workers.store import Store, load_npz

from ..deps import AuthDep, BackendDep, MetricsDep, StoreDep
from ..errors import ApiError, conflict, responses
from .databases import create_database

router = APIRouter(prefix="/v1/databases", tags=["databases"])


def _load(store: Store, db_id: str) -> Database:
    arrays = load_npz(store.database_arrays_bytes(db_id))
    return Database.from_arrays(library_from_arrays(arrays), arrays)


@router.post(
    "/{db_id}/corrections",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=DatabaseInfo,
    dependencies=[AuthDep],
    responses=responses(
        401,
        404,
        409,
        422,
        extra={200: {"model": DatabaseInfo, "description": "the corrected database exists"}},
    ),
)
async def correct_labels(
    db_id: str,
    corrections: Annotated[list[LabelCorrection], Body(min_length=1, max_length=10_000)],
    response: Response,
    store: StoreDep,
    backend: BackendDep,
    metrics: MetricsDep,
) -> DatabaseInfo:
    """Build the database with corrected labels (``set`` a label on a clip's frame range, or
    ``accept`` the propagated labels of a range); clips are named as in the database."""
    info = store.database_info(db_id)
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
    return await create_database(corrected, response, store, backend, metrics)


@router.get("/{db_id}/labels", responses=responses(404, 409, 422))
async def clip_labels(
    db_id: str,
    store: StoreDep,
    clip: Annotated[str, Query(min_length=1, description="clip as named in the database")],
    start: Annotated[int, Query(ge=0)] = 0,
    end: Annotated[int | None, Query(gt=0)] = None,
) -> dict[str, object]:
    """The labels of a clip of a ready ``annotated`` database as ranges (database frames): the user's
    where given, the SVMs' propagated labels elsewhere; what a client shows before it accepts or
    corrects them (``POST /v1/databases/{id}/corrections``)."""
    info = store.database_info(db_id)
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
