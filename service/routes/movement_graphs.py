"""``/v1/databases/{id}/graph`` and ``/graph-edits``: a rhythm database's movement transition graph
and the choreographer's edits of it (Kim, Park & Shin 2003, Sec. 4.3).

``GET .../graph`` describes the graph synthesis walks (groups with a representative clip span and
a thumbnail pose, transitions with their probability and kinematic and behavioural likelihoods).
``POST .../graph-edits`` connects, cuts and weights transitions (groups by id or by a clip span),
checks what the edits change (no new dead end, no group made unreachable that was reachable)
and stores the result as a derived,
content-addressed database (:mod:`workers.movement_graphs`): 201 when created, 200 when the same edits
of the same parent exist already. It is quick (the parent's arrays with one matrix replaced), so it
runs in a worker thread of the API, not as a job.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Response, status
from starlette.concurrency import run_in_threadpool

from engines.base import EngineError
from schemas import DatabaseInfo, DatabaseStatus
from schemas.movement_graph import GraphEdits, MovementGraph
from workers.movement_graphs import derive_in_store, graph_of, movement_graph_engine
from workers.store import Store

from ..deps import PrincipalDep, StoreDep
from ..errors import ApiError, conflict, responses
from ..jsonbody import json_body, json_body_doc
from ..owners import database_for

router = APIRouter(prefix="/v1/databases", tags=["databases"])

EDITS_BODY = json_body_doc(
    "GraphEdits", "Edits of the movement transition graph: connect, cut or weight transitions."
)
EditsBody = Annotated[GraphEdits, Depends(json_body(GraphEdits.model_validate))]


def _ready_graph(info: DatabaseInfo) -> None:
    """422 unless a database with a movement graph; 409 unless built."""
    try:
        movement_graph_engine(info)
    except EngineError as exc:
        raise ApiError(422, "invalid_request", str(exc)) from None
    if info.status != DatabaseStatus.ready:
        raise conflict("database_not_ready", f"database {info.id} is {info.status.value}")


def _graph(store: Store, info: DatabaseInfo) -> MovementGraph:
    with store.open_database(info.id) as arrays:
        return graph_of(arrays, info, store.database_spec(info.id))


@router.get("/{db_id}/graph", response_model=MovementGraph, responses=responses(401, 404, 409, 422))
async def movement_graph(db_id: str, store: StoreDep, principal: PrincipalDep) -> MovementGraph:
    """The movement transition graph of a ready rhythm database: groups (size, representative
    clip span, thumbnail pose) and the transitions synthesis draws from (probability, kinematic
    and behavioural likelihoods, learned or added by an edit)."""
    info = await run_in_threadpool(database_for, store, principal, db_id)
    _ready_graph(info)
    return await run_in_threadpool(_graph, store, info)


@router.post(
    "/{db_id}/graph-edits",
    status_code=status.HTTP_201_CREATED,
    response_model=DatabaseInfo,
    openapi_extra=EDITS_BODY,
    responses=responses(
        400,
        401,
        404,
        409,
        413,
        415,
        422,
        extra={200: {"model": DatabaseInfo, "description": "the same edits of this database exist"}},
    ),
)
async def edit_graph(
    db_id: str, response: Response, store: StoreDep, principal: PrincipalDep, body: EditsBody
) -> DatabaseInfo:
    """Derive a database whose movement graph has these edits (in order): ``connect``, ``cut`` or
    ``weight`` a transition between two groups, each named by id or by a clip span
    (``{"clip", "frames"|"seconds"}``). The edits must keep a transition out of every group and
    every group as reachable as it was (from every group that reached it); a 422 names the
    offending edit and the groups otherwise. The parent is untouched;
    the derived database records it and the edits (``derived_from``) and is used like any other."""
    info = await run_in_threadpool(database_for, store, principal, db_id)
    _ready_graph(info)
    try:
        derived, created = await run_in_threadpool(derive_in_store, store, info, body)
    except EngineError as exc:
        details = getattr(exc, "details", None)
        raise ApiError(422, "invalid_request", str(exc), details) from None
    store.add_owner("databases", derived.id, principal.name)
    if not created:
        response.status_code = status.HTTP_200_OK
    return derived
