"""``/v1/jobs``: submit synthesis jobs, read their status, cancel them, download results and reports."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request, Response, status
from starlette.concurrency import run_in_threadpool

from engines.registry import engine_class
from motion import ExportError
from motion.resample import resample
from schemas import DatabaseStatus, JobInfo, Report, parse_job_request
from schemas.jobs import JobKind, JobStatus
from workers.backend import JobBackend
from workers.inputs import InputError, resolve_inputs

from ..deps import AuthDep, BackendDep, MetricsDep, SettingsDep, StoreDep
from ..errors import ApiError, conflict, responses
from ..exports import MEDIA_TYPES, ExportTarget, ResultFormat, export_bytes
from ..jobs_common import submit_job
from ..uploads import read_body

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])

JOB_REQUEST_BODY = {
    "requestBody": {
        "required": True,
        "description": "A job request: the built-in engines' requests are shown; engine plugins add theirs.",
        "content": {"application/json": {"schema": {"$ref": "#/components/schemas/JobRequest"}}},
    }
}
"""The request body as documented (the schema is added by :func:`service.app.custom_openapi`); the
route parses the body itself with :func:`schemas.parse_job_request` so plugin engines work."""

ResultQuery = Annotated[str | None, Query(description="result id (default: the job's best result so far)")]


@router.post(
    "",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=JobInfo,
    dependencies=[AuthDep],
    openapi_extra=JOB_REQUEST_BODY,
    responses=responses(401, 404, 409, 413, 422),
)
async def submit(
    request: Request, store: StoreDep, backend: BackendDep, metrics: MetricsDep, settings: SettingsDep
) -> JobInfo:
    """Submit a synthesis job against a ready database; follow it with ``/v1/jobs/{id}/events``."""
    body = await read_body(request, settings.max_upload_bytes)
    job_request = parse_job_request(body)
    engine: str = job_request.engine  # type: ignore[attr-defined]
    if job_request.database is None:
        raise ApiError(422, "invalid_request", "the request names no database ('database': <database id>)")
    db = store.database_info(job_request.database)
    if db.status != DatabaseStatus.ready:
        detail = f" ({db.error})" if db.error else ""
        raise conflict(
            "database_not_ready",
            f"database {db.id} is {db.status.value}{detail}; submit once it is ready",
            {"database": db.id, "status": db.status.value, "build_job": db.build_job},
        )
    engine_cls = engine_class(engine)
    if engine_cls.kind != db.kind:
        raise ApiError(
            422,
            "wrong_database_kind",
            f"engine {engine!r} needs a {engine_cls.kind!r} database; database {db.id} is {db.kind!r}",
        )
    try:
        job_request.inputs = await run_in_threadpool(resolve_inputs, store, job_request)
    except InputError as exc:
        raise ApiError(422, "input_not_found", str(exc), {"inputs": job_request.input_files()}) from None
    payload = {"request": job_request.model_dump(mode="json")}
    return await submit_job(store, backend, metrics, JobKind.synth, payload, engine=engine, database=db.id)


@router.get("", response_model=list[JobInfo], responses=responses(422))
async def list_jobs(
    store: StoreDep,
    status_filter: Annotated[
        JobStatus | None, Query(alias="status", description="only jobs in this state")
    ] = None,
    limit: Annotated[int, Query(ge=1, le=1000, description="at most this many, newest first")] = 100,
) -> list[JobInfo]:
    """Jobs, newest first (status as last recorded in the store)."""
    jobs = await run_in_threadpool(store.list_jobs)
    if status_filter is not None:
        jobs = [j for j in jobs if j.status == status_filter]
    return jobs[::-1][:limit]


@router.get("/{job_id}", response_model=JobInfo, responses=responses(404, 422))
async def get_job(job_id: str, backend: BackendDep) -> JobInfo:
    """A job's status, best result so far and newest event id."""
    return await backend.status(job_id)


@router.post(
    "/{job_id}/cancel",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=JobInfo,
    dependencies=[AuthDep],
    responses=responses(401, 404, 422),
)
async def cancel(job_id: str, backend: BackendDep) -> JobInfo:
    """Ask a job to stop; it ends with a ``cancelled`` event carrying its best result so far."""
    return await backend.cancel(job_id)


async def _result_id(backend: JobBackend, job_id: str, result: str | None) -> str:
    if result is not None:
        return result
    info = await backend.status(job_id)
    if info.result is None:
        state = "has finished without a result" if info.status.finished else "has no result yet"
        raise ApiError(404, "not_found", f"job {job_id} {state} (status {info.status.value})")
    return info.result


@router.get(
    "/{job_id}/result",
    responses=responses(
        404,
        422,
        extra={
            200: {
                "description": "the result motion",
                "content": {media: {} for media in MEDIA_TYPES.values()},
            }
        },
    ),
    response_class=Response,
)
async def download_result(
    job_id: str,
    store: StoreDep,
    backend: BackendDep,
    format: Annotated[ResultFormat, Query(description="bvh, glb, json frames or npz")] = ResultFormat.bvh,
    result: ResultQuery = None,
    target: Annotated[
        ExportTarget, Query(description="axis/unit convention (not for glb)")
    ] = ExportTarget.gltf,
    fps: Annotated[
        float | None, Query(gt=0, le=1000, description="resample to this frame rate (default: as computed)")
    ] = None,
    max_fps: Annotated[
        float | None, Query(gt=0, le=1000, description="resample down to this rate only if faster (previews)")
    ] = None,
) -> Response:
    """Download a result motion (default: the job's best result so far), optionally resampled."""
    rid = await _result_id(backend, job_id, result)
    motion = store.result_motion(job_id, rid)
    try:
        if fps is None and max_fps is not None and motion.fps > max_fps:
            fps = max_fps
        if fps is not None and abs(fps - motion.fps) > 1e-9:
            motion = await run_in_threadpool(resample, motion, fps)
        data = await run_in_threadpool(export_bytes, motion, format, target)
    except ExportError as exc:
        raise ApiError(422, "export_failed", f"cannot export result {rid} as {format.value}: {exc}") from None
    filename = f"segue-{job_id}-{rid}.{format.value}"
    return Response(
        data,
        media_type=MEDIA_TYPES[format],
        headers={"Content-Disposition": f'attachment; filename="{filename}"'},
    )


@router.get("/{job_id}/report", response_model=Report, responses=responses(404, 422))
async def report(job_id: str, store: StoreDep, backend: BackendDep, result: ResultQuery = None) -> Report:
    """A result's report: score terms, constraint errors, metrics and per-frame provenance."""
    return store.result_report(job_id, await _result_id(backend, job_id, result))
