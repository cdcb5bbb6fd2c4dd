"""``/v1/databases``: build a database from uploaded clips and a spec, watch its status, delete it.

A database is content-addressed (:func:`schemas.databases.database_id`): posting the same clips
and spec again returns the existing database instead of building it twice.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Response, status

from engines.registry import kind_class
from schemas import ClipSource, DatabaseInfo, DatabaseSpec, DatabaseStatus
from schemas.databases import DatabaseSpecBase, database_id, parse_database_spec
from schemas.jobs import JobKind
from workers.store import NotFoundError, Store, now

from ..deps import AuthDep, BackendDep, MetricsDep, StoreDep
from ..errors import ApiError, conflict, responses
from ..jobs_common import new_job_id, submit_job

router = APIRouter(prefix="/v1/databases", tags=["databases"])


def resolve_clips(store: Store, spec: DatabaseSpecBase) -> tuple[DatabaseSpecBase, list[str]]:
    """The spec with every clip given by id (names kept), and the clips' content hashes.

    ``bvh`` is the file name of an uploaded clip, ``clip`` an uploaded clip's id (or file name).
    Raises :class:`~service.errors.ApiError`: 404 naming a missing clip, 422 for repeated names.
    """
    resolved: list[ClipSource] = []
    for i, source in enumerate(spec.clips):
        ref = source.clip or source.bvh or ""  # ClipSource guarantees exactly one of them
        try:
            info = store.find_clip(ref)
        except NotFoundError:
            field = "clip" if source.clip is not None else "bvh"
            raise ApiError(
                404,
                "not_found",
                f"clips[{i}]: no uploaded clip {ref!r}; upload it first (POST /v1/clips)",
                {"index": i, field: ref},
            ) from None
        name = source.name or ClipSource(bvh=source.bvh or info.name).display_name()
        resolved.append(source.model_copy(update={"clip": info.id, "bvh": None, "name": name}))
    names = [c.display_name() for c in resolved]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ApiError(
            422,
            "invalid_request",
            f"clip names must be unique in a database; repeated: {', '.join(repeated)} (give each a 'name')",
            {"repeated": repeated},
        )
    data = spec.model_dump(mode="json")
    data["clips"] = [c.model_dump(mode="json", exclude_none=True) for c in resolved]
    return parse_database_spec(data), [c.clip for c in resolved if c.clip is not None]


def _usable(store: Store, info: DatabaseInfo) -> bool:
    """True when an existing database is ready or still on its way (not worth a rebuild)."""
    if info.status == DatabaseStatus.ready:
        return True
    if info.status == DatabaseStatus.failed:
        return False
    if info.build_job is None:
        return False
    try:
        job = store.job_info(info.build_job)
    except NotFoundError:
        return False
    return not job.status.finished  # a finished build that left it unready: build again


@router.post(
    "",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=DatabaseInfo,
    dependencies=[AuthDep],
    responses=responses(
        401,
        404,
        422,
        extra={200: {"model": DatabaseInfo, "description": "this database exists (ready or building)"}},
    ),
)
async def create_database(
    spec: Annotated[DatabaseSpec, Body()],
    response: Response,
    store: StoreDep,
    backend: BackendDep,
    metrics: MetricsDep,
) -> DatabaseInfo:
    """Build a database from uploaded clips (202 with ``build_job``; follow its events), or return
    the existing one with the same content address (200)."""
    kind_class(spec.kind)  # 422 unavailable for kinds whose engine has not landed
    resolved, hashes = resolve_clips(store, spec)
    db_id = database_id(resolved, hashes)
    # No await between this check and the job being stored (in submit_job, before the backend is
    # awaited), so concurrent posts of one spec in this process start one build.
    try:
        existing = store.database_info(db_id)
    except NotFoundError:
        existing = None
    if existing is not None and _usable(store, existing):
        response.status_code = status.HTTP_200_OK
        return existing
    job_id = new_job_id()
    info = DatabaseInfo(
        id=db_id,
        kind=spec.kind,
        name=resolved.name,
        status=DatabaseStatus.queued,
        clips=[c.display_name() for c in resolved.clips],
        build_job=job_id,
        created_at=now(),
    )
    store.put_database_info(info, resolved.model_dump(mode="json"))
    await submit_job(
        store, backend, metrics, JobKind.build, {"database": db_id}, job_id=job_id, database=db_id
    )
    return store.database_info(db_id)


@router.get("", response_model=list[DatabaseInfo])
async def list_databases(store: StoreDep) -> list[DatabaseInfo]:
    """Every database, oldest first."""
    return store.list_databases()


@router.get("/{db_id}", response_model=DatabaseInfo, responses=responses(404, 422))
async def get_database(db_id: str, store: StoreDep) -> DatabaseInfo:
    """One database: its status (``queued``, ``building``, ``ready``, ``failed``) and facts."""
    return store.database_info(db_id)


@router.delete(
    "/{db_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    dependencies=[AuthDep],
    responses=responses(401, 404, 409, 422),
)
async def delete_database(db_id: str, store: StoreDep) -> Response:
    """Delete a database (409 while it is being built)."""
    info = store.database_info(db_id)
    if info.status in (DatabaseStatus.queued, DatabaseStatus.building) and _usable(store, info):
        raise conflict("database_building", f"database {db_id} is {info.status.value}; delete it once built")
    store.delete_database(db_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
