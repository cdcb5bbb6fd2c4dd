"""``/v1/databases``: build a database from uploaded clips and a spec, watch its status, delete it.

A database is content-addressed (:func:`schemas.databases.database_id`): posting the same clips
and spec again returns the existing database instead of building it twice.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request, Response, status
from pydantic import TypeAdapter
from starlette.concurrency import run_in_threadpool

from engines.registry import kind_class, parse_database_spec, require_kind, spec_union
from motion import MotionError
from motion.resample import resampled_frames
from schemas import ClipSource, DatabaseInfo, DatabaseStatus
from schemas.bases import DatabaseSpecBase
from schemas.clips import labels_past_clip_end
from schemas.databases import DatabaseSummary, database_id
from schemas.jobs import JobKind
from workers.backend import JobBackend
from workers.budget import database_frames
from workers.samples import store_sample
from workers.store import NotFoundError, Store, now
from workers.summary import database_summary

from ..deps import BackendDep, JobQuotaDep, MetricsDep, Principal, PrincipalDep, SettingsDep, StoreDep
from ..errors import ApiError, conflict, responses
from ..jobs_common import new_job_id, submit_job
from ..jsonbody import delete_route, json_body, json_body_doc
from ..metrics import Metrics
from ..owners import database_for, find_clip, only_visible, record, release, seen

SPEC_ADAPTER: TypeAdapter[Any] = TypeAdapter(spec_union())
SPEC_BODY = json_body_doc("DatabaseSpec", "A database spec: the clips (uploaded) and the kind's settings.")


def validate_spec(value: object) -> DatabaseSpecBase:
    """A parsed JSON body as a database spec of any kind (pydantic's ``ValidationError`` otherwise)."""
    spec: DatabaseSpecBase = SPEC_ADAPTER.validate_python(value)
    return spec


SpecBody = Annotated[DatabaseSpecBase, Depends(json_body(validate_spec))]

router = APIRouter(prefix="/v1/databases", tags=["databases"])


def resolve_clips(
    store: Store, spec: DatabaseSpecBase, principal: Principal, shared: frozenset[str] = frozenset()
) -> tuple[DatabaseSpecBase, list[str]]:
    """The spec with every clip given by id (names kept), and the clips' content hashes.

    ``bvh`` is the file name of an uploaded clip or ``sample:NAME`` (a bundled sample, stored and
    held by the principal on first use), ``clip`` an uploaded clip's id (or file name), among the
    principal's clips and the ``shared`` ids (the clips of a database it holds, for corrections).
    Raises :class:`~service.errors.ApiError`: 404 naming a missing clip, 422 for repeated names.
    """
    resolved: list[ClipSource] = []
    for i, source in enumerate(spec.clips):
        ref = source.clip or source.bvh or ""  # ClipSource guarantees exactly one of them
        try:
            sample = store_sample(store, source.bvh) if source.bvh is not None else None
        except MotionError as exc:
            raise ApiError(404, "not_found", f"clips[{i}]: {exc}", {"index": i, "bvh": ref}) from None
        try:
            if sample is not None and sample[1] is not None:
                info = sample[1]
                store.add_owner("clips", info.id, principal.name, record(info.name))
            else:
                info = find_clip(store, principal, ref, shared)
        except NotFoundError:
            field = "clip" if source.clip is not None else "bvh"
            raise ApiError(
                404,
                "not_found",
                f"clips[{i}]: no uploaded clip {ref!r}; upload it first (POST /v1/clips)",
                {"index": i, field: ref},
            ) from None
        name = source.name or ClipSource(bvh=source.bvh or info.name).display_name()
        update: dict[str, Any] = {"clip": info.id, "bvh": None, "name": name}
        if source.units is None and info.units != store.clip_info(info.id).units:
            update["units"] = info.units  # the principal's own unit for shared bytes
        resolved.append(source.model_copy(update=update))
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
    openapi_extra=SPEC_BODY,
    responses=responses(
        400,
        401,
        404,
        413,
        415,
        422,
        429,
        503,
        extra={200: {"model": DatabaseInfo, "description": "this database exists (ready or building)"}},
    ),
)
async def create_database(
    response: Response,
    store: StoreDep,
    backend: BackendDep,
    metrics: MetricsDep,
    settings: SettingsDep,
    quota: JobQuotaDep,
    principal: PrincipalDep,
    spec: SpecBody,
    request: Request,
) -> DatabaseInfo:
    """Build a database from uploaded clips (202 with ``build_job``; follow its events), or return
    the existing one with the same content address (200)."""
    quota.check(principal.name)
    info = await create_from_spec(
        spec,
        response,
        store,
        backend,
        metrics,
        principal,
        max_frames=settings.max_database_frames,
        work_limits=(settings.max_build_cpu_s, float(settings.max_job_memory_mb)),
    )
    if info.build_job and response.status_code != status.HTTP_200_OK:  # a build was queued (202)
        quota.add(principal.name, info.build_job)
    return await run_in_threadpool(with_summary, request.app.state, store, info)


def check_database_size(
    store: Store,
    spec: DatabaseSpecBase,
    hashes: list[str],
    limit: int | None,
    work_limits: tuple[float, float] | None = None,
) -> None:
    """413 ``over_budget`` when the database would be too big to build. Kinds whose engine estimates
    its build (``Engine.build_work``: the graph) are bounded by ``work_limits`` (CPU seconds, MiB
    of memory; 0 = no limit); others hold at most ``limit`` frames at their rate."""
    clips = [(info.frames, info.fps) for info in (store.clip_info(h) for h in hashes)]
    engine = kind_class(spec.kind)
    total = engine.library_frames(spec, database_frames(clips, spec.fps))  # mirror images count
    work = engine.build_work(spec, total) if work_limits is not None else None
    if work is not None and work_limits is not None:
        max_cpu, max_mb = work_limits
        if (max_cpu and work.cpu_s > max_cpu) or (max_mb and work.memory_mb > max_mb):
            raise ApiError(
                413,
                "over_budget",
                f"building the database ({total} frames at its rate) would take about {work.cpu_s:.0f} CPU "
                f"seconds and {work.memory_mb:.0f} MiB, over the limits of {max_cpu:g} s "
                f"(SEGUE_MAX_BUILD_CPU_S) and {max_mb:g} MiB (SEGUE_MAX_JOB_MEMORY_MB)",
                {
                    "frames": total,
                    "cpu_s": round(work.cpu_s),
                    "memory_mb": round(work.memory_mb),
                    "max_build_cpu_s": max_cpu,
                    "max_job_memory_mb": max_mb,
                },
            )
        return
    if limit is None:
        return
    if total > limit:
        raise ApiError(
            413,
            "over_budget",
            f"the database would hold {total} frames at its rate, over the limit of {limit} "
            "(SEGUE_MAX_DATABASE_FRAMES)",
            {"frames": total, "limit": limit},
        )


def check_label_ranges(store: Store, spec: DatabaseSpecBase, hashes: list[str]) -> None:
    """422 ``invalid_request`` naming every label range that ends after its clip (ranges are frames
    at the database rate: the spec's ``fps``, else the first clip's)."""
    if not any(c.labels for c in spec.clips):
        return
    infos = [store.clip_info(h) for h in hashes]
    rate = spec.fps or infos[0].fps
    frames = [resampled_frames(info.frames, info.fps, rate) for info in infos]
    problems = labels_past_clip_end(spec.clips, frames, rate)
    if problems:
        raise ApiError(422, "invalid_request", "; ".join(problems), {"problems": problems})


def check_clips(store: Store, spec: DatabaseSpecBase, hashes: list[str]) -> None:
    """422 ``invalid_request`` naming every problem the build would meet that the clips' infos
    show: an ``animation`` a glTF clip lacks (or given for a BVH clip), clips of different
    skeletons (with the fix: retarget), and what the kind's engine refuses from the clips' lengths
    (:meth:`engines.base.Engine.spec_problems`: a control pair of unequal lengths)."""
    infos = [store.clip_info(h) for h in hashes]
    problems: list[str] = []
    lengths: list[tuple[int, float]] = []
    for i, (source, info) in enumerate(zip(spec.clips, infos, strict=True)):
        frames, fps = info.frames, info.fps
        if source.animation is not None:
            names = [a.name for a in info.animations]
            if info.format != "gltf":
                problems.append(
                    f"clips[{i}] ({source.display_name()}): 'animation' is for glTF clips; a BVH holds one"
                )
            else:
                wanted = source.animation
                k = names.index(wanted) if isinstance(wanted, str) and wanted in names else None
                if k is None and isinstance(wanted, int) and 0 <= wanted < len(names):
                    k = wanted
                if k is None:
                    listed = ", ".join(f"{j}: {n!r}" for j, n in enumerate(names))
                    problems.append(
                        f"clips[{i}] ({source.display_name()}): no animation {wanted!r}; the file has "
                        f"{listed}"
                    )
                else:
                    frames, fps = info.animations[k].frames, info.animations[k].fps
        lengths.append((frames, fps))
    first = infos[0] if infos else None
    for i, info in enumerate(infos[1:], start=1):
        if first is not None and info.joints != first.joints:
            a, b = spec.clips[i].display_name(), spec.clips[0].display_name()
            problems.append(
                f"clips[{i}] ({a}) has another skeleton than clips[0] ({b}) ({len(info.joints)} joints, "
                f"{len(first.joints)}): a database's clips share one; retarget it onto the skeleton of {b} "
                f"first (segue retarget FILE_OF_{a} --to FILE_OF_{b} --out NEW.bvh) and upload the new file"
            )
    if not problems and lengths:
        rate = spec.fps or lengths[0][1]
        names = [c.display_name() for c in spec.clips]
        frames_at = {n: resampled_frames(f, r, rate) for n, (f, r) in zip(names, lengths, strict=True)}
        problems += kind_class(spec.kind).spec_problems(spec, frames_at, rate)
    if problems:
        raise ApiError(422, "invalid_request", "; ".join(problems), {"problems": problems})


async def create_from_spec(
    spec: DatabaseSpecBase,
    response: Response,
    store: Store,
    backend: JobBackend,
    metrics: Metrics,
    principal: Principal,
    shared: frozenset[str] = frozenset(),
    max_frames: int | None = None,
    work_limits: tuple[float, float] | None = None,
) -> DatabaseInfo:
    """The body of ``POST /v1/databases`` once the spec is valid (also used by corrections)."""
    require_kind(spec.kind)  # 422 unavailable for kinds whose engine has not landed
    resolved, hashes = await run_in_threadpool(resolve_clips, store, spec, principal, shared)
    await run_in_threadpool(check_database_size, store, resolved, hashes, max_frames, work_limits)
    await run_in_threadpool(check_clips, store, resolved, hashes)
    await run_in_threadpool(check_label_ranges, store, resolved, hashes)
    db_id = database_id(resolved, hashes)
    # No await between this check and the job being stored (in submit_job, before the backend is
    # awaited), so concurrent posts of one spec in this process start one build.
    try:
        existing = store.database_info(db_id)
    except NotFoundError:
        existing = None
    if existing is not None and _usable(store, existing):
        store.add_owner("databases", db_id, principal.name, record(resolved.name, build_job=None))
        response.status_code = status.HTTP_200_OK
        return seen(store, principal, "databases", existing)
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
    try:
        await submit_job(
            store,
            backend,
            metrics,
            JobKind.build,
            {"database": db_id},
            job_id=job_id,
            database=db_id,
            owner=principal.name,
        )
    except BaseException:
        # the build was not queued (the backend is down): leave no database that never builds
        if existing is not None:
            store.put_database_info(existing)
        else:
            store.delete_database(db_id)
        raise
    store.add_owner("databases", db_id, principal.name, record(resolved.name, build_job=job_id), replace=True)
    return seen(store, principal, "databases", store.database_info(db_id))


def summary_of(state: Any, store: Store, db_id: str) -> DatabaseSummary | None:
    """The summary of a ready database (computed once per process: a ready database never
    changes); None when it has no data (deleted meanwhile, or older arrays)."""
    cache: dict[str, DatabaseSummary] | None = getattr(state, "database_summaries", None)
    if cache is None:
        cache = state.database_summaries = {}
    summary = cache.get(db_id)
    if summary is None:
        try:
            summary = cache[db_id] = database_summary(store, db_id)
        except (NotFoundError, KeyError, ValueError, OSError):
            return None
        while len(cache) > 1024:
            cache.pop(next(iter(cache)))
    return summary


def with_summary(state: Any, store: Store, info: DatabaseInfo) -> DatabaseInfo:
    """``info`` with the summary of a ready database (:func:`summary_of`)."""
    if info.status != DatabaseStatus.ready:
        return info
    summary = summary_of(state, store, info.id)
    if summary is None:
        return info
    return info.model_copy(update={"summary": summary})


@router.get("", response_model=list[DatabaseInfo], responses=responses(401))
async def list_databases(request: Request, store: StoreDep, principal: PrincipalDep) -> list[DatabaseInfo]:
    """Your databases, oldest first (ready ones with their ``summary``)."""
    found = await run_in_threadpool(only_visible, store, principal, "databases", store.list_databases())
    return await run_in_threadpool(lambda: [with_summary(request.app.state, store, d) for d in found])


@router.get("/{db_id}", response_model=DatabaseInfo, responses=responses(401, 404, 422))
async def get_database(
    db_id: str, request: Request, store: StoreDep, principal: PrincipalDep
) -> DatabaseInfo:
    """One of your databases: its status (``queued``, ``building``, ``ready``, ``failed``) and facts;
    a ready one with its ``summary`` (kind, clips with their labels, label vocabulary, skeleton,
    units), so any client can use a database it did not build."""
    info = database_for(store, principal, db_id)
    return await run_in_threadpool(with_summary, request.app.state, store, info)


@router.delete("/{db_id}", **delete_route(409))
def delete_database(db_id: str, store: StoreDep, principal: PrincipalDep) -> Response:
    """Delete your database (409 while it is being built, or while your unfinished jobs use it). The
    data goes when no other principal holds the same database; other principals' jobs on it are
    theirs (your hold goes, their data stays)."""
    info = store.database_info(database_for(store, principal, db_id).id)  # the shared record: the build
    if info.status in (DatabaseStatus.queued, DatabaseStatus.building) and _usable(store, info):
        raise conflict("database_building", f"database {db_id} is {info.status.value}; delete it once built")
    users = [
        j
        for j in store.list_jobs()
        if j.database == db_id and j.id != info.build_job and not j.status.finished
    ]
    mine = [j.id for j in users if principal.may(j.owner)]
    if mine:
        raise conflict(
            "database_in_use",
            f"{len(mine)} unfinished job(s) of yours use database {db_id}; cancel them or wait for them "
            "to end",
            {"jobs": mine[:20]},
        )
    if len(users) > len(mine) and not (store.owners("databases", db_id) - {principal.name}):
        # the last hold, and jobs of others (an admin's) still read the data: not now, naming none
        raise conflict(
            "database_in_use",
            f"database {db_id} is still in use; try again later",
            {"jobs": []},
        )
    return release(store, principal, "databases", db_id, store.delete_database)
