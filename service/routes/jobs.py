"""``/v1/jobs``: submit synthesis jobs, read their status, cancel them, download results and reports."""

from __future__ import annotations

from typing import Annotated

import anyio
from fastapi import APIRouter, Depends, Query, Request, Response, status
from starlette.concurrency import run_in_threadpool

from engines.registry import parse_job_request
from schemas import JobInfo, Report
from schemas.bases import JobRequestBase
from schemas.common import FeetMode
from schemas.jobs import JobKind, JobStatus
from workers.backend import JobBackend, JobNotFinished
from workers.budget import check_work, database_facts, estimate_work
from workers.prepare import Prepared, PrepareError, prepare
from workers.result_export import ExportSpec
from workers.store import Store

from ..characters import RestPose, RootMotion, character_ref
from ..deps import (
    BackendDep,
    JobQuotaDep,
    MetricsDep,
    ParseLimiterDep,
    Principal,
    PrincipalDep,
    SettingsDep,
    StoreDep,
)
from ..errors import ApiError, conflict, responses
from ..exports import MEDIA_TYPES, ExportTarget, ExportUnits, ResultFormat, ResultMesh, result_download
from ..jobs_common import submit_job
from ..jsonbody import BodylessWrite, delete_route, json_body, json_body_doc
from ..owners import database_for, job_for, visible
from ..settings import Settings
from ..tasks import TaskRunnerDep

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])

JOB_REQUEST_BODY = json_body_doc(
    "JobRequest", "A job request: the built-in engines' requests are shown; engine plugins add theirs."
)
"""The request body as documented (the schema is added by :func:`service.app.create_app`); the
route parses the body itself with :func:`engines.registry.parse_job_request` so plugin engines work."""

JobRequestBody = Annotated[JobRequestBase, Depends(json_body(parse_job_request))]
ResultQuery = Annotated[
    str | None,
    Query(
        pattern=r"^[0-9a-z_-]{1,80}$",
        description="result id: lowercase letters, digits, '-' and '_' (default: the job's best result)",
    ),
]


@router.post(
    "",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=JobInfo,
    openapi_extra=JOB_REQUEST_BODY,
    responses=responses(400, 401, 404, 409, 413, 415, 422, 429, 503),
)
async def submit(
    store: StoreDep,
    backend: BackendDep,
    metrics: MetricsDep,
    settings: SettingsDep,
    quota: JobQuotaDep,
    limiter: ParseLimiterDep,
    principal: PrincipalDep,
    job_request: JobRequestBody,
    request: Request,
) -> JobInfo:
    """Submit a synthesis job against a ready database; follow it with ``/v1/jobs/{id}/events``.

    The request's work (output frames x characters x joints, memory, time) is checked against the
    server's limits first: 413 ``over_budget`` names each number over its limit. What it names of
    the database is checked against the database's summary: 422 ``unknown_joint``,
    ``unknown_label`` (a timeline or label constraint outside the label vocabulary) or
    ``unknown_clip`` (a clip the database lacks, or a frame past a clip's end at the database
    rate), each problem named, before a job is queued."""
    mine = visible(store, principal, "clips", "files")

    def prepared() -> Prepared:
        return prepare(
            job_request,
            store,
            visible=mine,
            database=lambda db_id: database_for(store, principal, db_id),
            holder=principal.name,
        )

    try:
        db = (await run_in_threadpool(prepared)).database
    except PrepareError as exc:
        raise ApiError(exc.status, exc.code, exc.message, exc.details or None) from None
    await _check_budget(settings, store, limiter, job_request)
    await _check_joints(store, job_request)
    await _check_names(request, store, job_request)
    quota.check(principal.name)
    payload = {"request": job_request.model_dump(mode="json")}
    info = await submit_job(
        store,
        backend,
        metrics,
        JobKind.synth,
        payload,
        engine=job_request.engine,
        database=db.id,
        owner=principal.name,
    )
    quota.add(principal.name, info.id)
    return info


async def _check_joints(store: Store, job_request: JobRequestBase) -> None:
    """422 ``unknown_joint`` when a request names a joint the database's skeleton lacks."""
    named = job_request.named_joints()
    if not named:
        return
    names = (await run_in_threadpool(database_facts, store, str(job_request.database))).joint_names
    missing = [(where, joint) for where, joint in named if names and joint not in names]
    if missing:
        shown = ", ".join(names[:16]) + (f", ... (+{len(names) - 16})" if len(names) > 16 else "")
        problems = [
            f"{where}: the database's skeleton has no joint named {joint!r}" for where, joint in missing
        ]
        raise ApiError(
            422,
            "unknown_joint",
            f"{'; '.join(problems)} (joints: {shown})",
            {"unknown": [f"{where}: {joint!r}" for where, joint in missing], "joints": list(names)},
        )


async def _check_names(request: Request, store: Store, job_request: JobRequestBase) -> None:
    """422 ``unknown_label`` / ``unknown_clip`` naming every label outside the database's
    vocabulary and every clip frame it lacks (:meth:`JobRequestBase.named_labels`,
    :meth:`JobRequestBase.named_clip_frames`; the database's summary)."""
    labels, frames = job_request.named_labels(), job_request.named_clip_frames()
    if not labels and not frames:
        return
    from .databases import summary_of

    summary = await run_in_threadpool(summary_of, request.app.state, store, str(job_request.database))
    if summary is None:
        return
    vocabulary = set(summary.labels)
    shown = ", ".join(repr(x) for x in summary.labels[:24]) or "none: no clip of the database is labelled"
    problems = [
        f"{where}: label {label!r} is not in the database's vocabulary ({shown})"
        for where, label, required in labels
        if required and label not in vocabulary
    ]
    code = "unknown_label" if problems else "unknown_clip"
    counts = {c.name: c.frames for c in summary.clips}
    names = ", ".join(repr(c) for c in list(counts)[:16]) + (", ..." if len(counts) > 16 else "")
    for where, clip, frame in frames:
        n = counts.get(clip)
        if n is None:
            problems.append(f"{where}: the database has no clip named {clip!r} (clips: {names})")
        elif frame >= n:
            problems.append(
                f"{where}: frame {frame} is past the end of clip {clip!r}, which has {n} frames at the "
                f"database rate ({summary.fps:g} fps; frames 0-{n - 1})"
            )
    if problems:
        raise ApiError(
            422,
            code,
            "; ".join(problems),
            {"problems": problems, "labels": summary.labels, "clips": counts},
        )


async def _check_budget(
    settings: Settings, store: Store, limiter: anyio.CapacityLimiter, job_request: JobRequestBase
) -> None:
    """413 ``over_budget`` when the request asks for more work than the server's limits allow."""
    facts = await run_in_threadpool(database_facts, store, str(job_request.database))
    work = await anyio.to_thread.run_sync(estimate_work, job_request, facts, limiter=limiter)
    problems = check_work(work, settings.work_limits)
    if problems:
        raise ApiError(
            413,
            "over_budget",
            "the request asks for more work than this server allows: " + "; ".join(problems),
            {"estimate": work.as_dict(), "limits": settings.work_limits_dict(), "problems": problems},
        )


@router.get("", response_model=list[JobInfo], responses=responses(401, 422))
async def list_jobs(
    store: StoreDep,
    principal: PrincipalDep,
    status_filter: Annotated[
        JobStatus | None, Query(alias="status", description="only jobs in this state")
    ] = None,
    limit: Annotated[int, Query(ge=1, le=1000, description="at most this many, newest first")] = 100,
) -> list[JobInfo]:
    """Your jobs, newest first (status as last recorded in the store)."""
    jobs = [
        j
        for j in await run_in_threadpool(store.list_jobs)
        if principal.may(j.owner) and j.kind != JobKind.task  # small jobs are the server's own
    ]
    if status_filter is not None:
        jobs = [j for j in jobs if j.status == status_filter]
    return jobs[::-1][:limit]


async def owned_job(backend: JobBackend, principal: Principal, job_id: str) -> JobInfo:
    """A job's status when the principal owns it (404 otherwise)."""
    return job_for(principal, await backend.status(job_id))


@router.get("/{job_id}", response_model=JobInfo, responses=responses(401, 404, 422))
async def get_job(job_id: str, backend: BackendDep, principal: PrincipalDep) -> JobInfo:
    """A job's status, best result so far and newest event id."""
    return await owned_job(backend, principal, job_id)


@router.post(
    "/{job_id}/cancel",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=JobInfo,
    dependencies=[BodylessWrite],
    responses=responses(401, 404, 415, 422, 503),
)
async def cancel(job_id: str, backend: BackendDep, principal: PrincipalDep) -> JobInfo:
    """Ask a job to stop; it ends with a ``cancelled`` event carrying its best result so far (no
    body needed: ``curl -X POST .../cancel``)."""
    await owned_job(backend, principal, job_id)
    return await backend.cancel(job_id)


@router.delete("/{job_id}", **delete_route(409, 503))
async def delete_job(job_id: str, backend: BackendDep, principal: PrincipalDep) -> Response:
    """Delete a finished job (``done``, ``failed`` or ``cancelled``): its record, events, results and
    reports. A job still queued or running is 409 ``job_not_finished``: cancel it first (``POST
    /v1/jobs/{id}/cancel``) and delete it once its terminal event has come. Databases the job built
    stay."""
    info = await owned_job(backend, principal, job_id)
    try:
        await backend.delete(job_id)
    except JobNotFinished:
        raise conflict(
            "job_not_finished",
            f"job {job_id} is {info.status.value}; cancel it first (POST /v1/jobs/{job_id}/cancel), then "
            "delete it once it has ended",
            {"job": job_id, "status": info.status.value},
        ) from None
    return Response(status_code=status.HTTP_204_NO_CONTENT)


async def _result_id(backend: JobBackend, principal: Principal, job_id: str, result: str | None) -> str:
    info = await owned_job(backend, principal, job_id)
    if result is not None:
        return result
    if info.result is None:
        if not info.status.finished:
            raise conflict(
                "result_not_ready",
                f"job {job_id} has no result yet (status {info.status.value}); follow "
                f"/v1/jobs/{job_id}/events for its first solution",
                {"job": job_id, "status": info.status.value},
            )
        raise ApiError(
            404, "not_found", f"job {job_id} has finished without a result (status {info.status.value})"
        )
    return info.result


@router.get(
    "/{job_id}/result",
    responses=responses(
        401,
        404,
        409,
        413,
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
    metrics: MetricsDep,
    runner: TaskRunnerDep,
    limiter: ParseLimiterDep,
    principal: PrincipalDep,
    settings: SettingsDep,
    format: Annotated[ResultFormat, Query(description="bvh, glb, json frames or npz")] = ResultFormat.bvh,
    result: ResultQuery = None,
    target: Annotated[
        ExportTarget,
        Query(
            description="axis/unit convention (not for glb); with character, also its root-motion convention"
        ),
    ] = ExportTarget.gltf,
    fps: Annotated[
        float | None,
        Query(ge=0.5, le=1000, description="resample to this frame rate (default: as computed)"),
    ] = None,
    max_fps: Annotated[
        float | None,
        Query(ge=0.5, le=1000, description="resample down to this rate only if faster (previews)"),
    ] = None,
    character: Annotated[
        str | None,
        Query(
            max_length=255,
            description="retarget onto this character: an uploaded clip (BVH, id or name) or file (GLB)",
        ),
    ] = None,
    rest: Annotated[
        RestPose, Query(description="a BVH character's rest pose: first frame or zero")
    ] = RestPose.first,
    units: Annotated[
        ExportUnits | None, Query(description="length unit (default: the target's; glb is m)")
    ] = None,
    in_place: Annotated[
        bool, Query(description="glb: body over the origin, root motion on the ground joint")
    ] = False,
    root_motion: Annotated[
        RootMotion | None,
        Query(
            description="with character: root motion on the root bone, the hips or none (default: target's)"
        ),
    ] = None,
    events: Annotated[
        str | None,
        Query(max_length=40, description="glb/json: contacts,beats,labels or all (glTF extras / events)"),
    ] = None,
    mesh: Annotated[
        ResultMesh | None,
        Query(description="glb: the mesh it wears: bones, body (Segue's mannequin) or none (default bones)"),
    ] = None,
    animation_only: Annotated[
        bool,
        Query(description="glb onto a glTF/GLB character: its skeleton and the animation only, no mesh"),
    ] = False,
    dancer: Annotated[
        int | None,
        Query(
            ge=0,
            le=100_000,
            description="one dancer of a result of several (crowds, couples, graph characters), "
            "its joints without their c0_ prefix; with character, that dancer on it",
        ),
    ] = None,
    feet: Annotated[
        FeetMode | None,
        Query(
            description="lock: planted feet held in place and on the floor; grounding: on the floor "
            "only; free: as they are (default: lock with character, free without)"
        ),
    ] = None,
) -> Response:
    """Download a result motion (default: the job's best result so far), optionally resampled or
    retargeted onto a character; 409 ``result_not_ready`` while the job has none yet, 422
    ``retarget_failed`` when the character's joints do not correspond. Each download is made once
    (large ones and retargetings by a worker) and streamed from the store."""
    rid = await _result_id(backend, principal, job_id, result)
    char = None
    if character is not None:
        char = await run_in_threadpool(character_ref, store, principal, character)
    if mesh is not None and (format != ResultFormat.glb or (char is not None and char.kind == "file")):
        raise ApiError(
            422,
            "invalid_request",
            "mesh= is for format=glb without a glTF character (a glTF character wears its own mesh)",
        )
    limits = settings.bvh_limits
    spec = ExportSpec(
        job=job_id,
        result=rid,
        format=format,
        target=target,
        fps=fps,
        max_fps=max_fps,
        character=char,
        rest=rest,
        units=units,
        in_place=in_place,
        root_motion=root_motion,
        events=events,
        mesh=mesh or ResultMesh.bones,
        animation_only=animation_only,
        dancer=dancer,
        feet=feet,
        max_frames=settings.max_output_frames,
        max_joint_frames=settings.max_joint_frames,
        bvh_limits=(limits.max_joints, limits.max_frames, limits.max_bytes),
    )
    return await result_download(spec, store, backend, metrics, runner, limiter, principal.name)


@router.get("/{job_id}/report", response_model=Report, responses=responses(401, 404, 409, 422))
async def report(
    job_id: str, store: StoreDep, backend: BackendDep, principal: PrincipalDep, result: ResultQuery = None
) -> Report:
    """A result's report: score terms, constraint errors, metrics and per-frame provenance (409
    ``result_not_ready`` before the job's first solution)."""
    return await run_in_threadpool(
        store.result_report, job_id, await _result_id(backend, principal, job_id, result)
    )
