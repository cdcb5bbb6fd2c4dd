"""``/v1/clips``: upload motions (BVH, plain or gzip; glTF/GLB with a skin and an animation), list,
get and delete them."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response, status
from starlette.concurrency import run_in_threadpool

from motion.samples import upload_units
from motion.units import METRES_PER_UNIT, guess_units
from schemas import ClipInfo

from ..deps import BackendDep, MetricsDep, ParseLimiterDep, PrincipalDep, SettingsDep, StoreDep
from ..errors import ApiError, responses
from ..jsonbody import delete_route
from ..owners import clip_for, hold, only_visible, release, seen
from ..tasks import TaskRunnerDep
from ..uploads import INLINE_UPLOAD_BYTES, Upload, parse_upload, receive_upload, stored, upload_body

router = APIRouter(prefix="/v1/clips", tags=["clips"])

UnitName = StrEnum("UnitName", {u: u for u in METRES_PER_UNIT})  # type: ignore[misc]
"""The length units a clip may declare (:data:`motion.units.METRES_PER_UNIT`)."""

_UPLOAD_BODY = upload_body(
    "A BVH file (``.bvh`` or gzip ``.bvh.gz``) or a glTF file with a skin and an animation (``.glb``, "
    "or ``.gltf`` with its buffers inline): as multipart field ``file``, or as the raw body with ``?name=``."
)


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=ClipInfo,
    openapi_extra=_UPLOAD_BODY,
    responses=responses(
        400,
        401,
        413,
        422,
        503,
        extra={200: {"model": ClipInfo, "description": "the same bytes were already uploaded"}},
    ),
)
async def upload_clip(
    request: Request,
    response: Response,
    store: StoreDep,
    backend: BackendDep,
    metrics: MetricsDep,
    runner: TaskRunnerDep,
    settings: SettingsDep,
    limiter: ParseLimiterDep,
    principal: PrincipalDep,
    name: Annotated[str | None, Query(max_length=255, description="file name (raw-body uploads)")] = None,
    units: Annotated[
        UnitName | None, Query(description="declared length unit (default: guessed from the height)")
    ] = None,
) -> ClipInfo:
    """Upload a clip: a BVH file, or a glTF/GLB file's animation (its first; ``animations`` lists them
    all, a database spec's ``animation`` picks another). It is parsed and checked against the frame,
    joint and joint-frame limits (a BVH header here, a large clip's frames by a worker: the answer
    waits for it). ``warnings`` in the answer say what the file needed to be read (a ``Frames:``
    count that disagrees with the frame lines, decimal commas, missing End Sites...): it was read,
    and they say how.

    A bundled sample's own file (as ``GET /samples`` serves it) is read in the unit the sample
    catalogue declares unless ``units`` says otherwise. Stored once per content hash: 201 for a
    new clip, 200 when you uploaded the same bytes before (409 ``units_conflict`` when you uploaded
    them in other ``units``). Bytes another principal uploaded answer as if you were the first: in
    your ``units`` (declared, or guessed as for a new upload), whatever theirs.
    """
    async with receive_upload(request, settings.max_upload_bytes, name) as upload:
        existing = await run_in_threadpool(stored, store.clip_info, upload.digest)
        own: dict[str, Any] = {}
        if existing is None:
            unit = units.value if units is not None else await _sample_units(upload)
            existing = await parse_upload(
                upload, unit, settings.bvh_limits, store, backend, metrics, runner, limiter, principal.name
            )
        elif principal.name in await run_in_threadpool(store.owners, "clips", existing.id):
            mine = await run_in_threadpool(seen, store, principal, "clips", existing)
            if units is not None and units.value != mine.units:
                raise ApiError(
                    409,
                    "units_conflict",
                    f"you uploaded these bytes before as clip {mine.id} in units {mine.units!r}; a "
                    f"clip's units cannot change (delete it first to upload it again with "
                    f"units={units.value!r})",
                    {"clip": mine.id, "units": mine.units},
                )
        else:
            declared = units.value if units is not None else await _sample_units(upload)
            own = holder_units(existing, upload.name, declared)
        clip = existing
        await run_in_threadpool(
            hold,
            store,
            principal,
            "clips",
            clip.id,
            response,
            upload.name,
            lambda: store.restore_clip(clip, upload.file),
            own,
        )
    return await run_in_threadpool(seen, store, principal, "clips", clip)


async def _sample_units(upload: Upload) -> str | None:
    """The declared unit of an upload that is a bundled sample's own file (samples are small: a
    larger upload is none)."""
    if upload.size > INLINE_UPLOAD_BYTES:
        return None
    return upload_units(upload.name, await run_in_threadpool(upload.read))


def holder_units(shared: ClipInfo, file_name: str, units: str | None) -> dict[str, Any]:
    """A new holder's own ``units`` and ``height_m`` for bytes another principal uploaded, as a
    first upload would have read them (``units``: declared, or the sample catalogue's; else the
    guess from the height); empty when they are the shared record's. Raises
    :class:`~service.errors.ApiError` 400 for a unit a glTF file cannot have (as a first upload)."""
    if shared.format == "gltf":
        if units not in (None, "m"):
            raise ApiError(
                400,
                "invalid_bvh",
                f"{file_name}: a glTF file is in metres (glTF's rule); units {units!r} do not apply",
            )
        return {}
    if shared.units not in METRES_PER_UNIT:
        return {}
    file_height = shared.height_m / METRES_PER_UNIT[shared.units]
    unit = units or guess_units(file_height).units
    if unit == shared.units or unit not in METRES_PER_UNIT:
        return {}
    return {"units": unit, "height_m": round(file_height * METRES_PER_UNIT[unit], 4)}


@router.get("", response_model=list[ClipInfo], responses=responses(401))
def list_clips(store: StoreDep, principal: PrincipalDep) -> list[ClipInfo]:
    """Your uploaded clips (under the names you gave them), oldest first."""
    return only_visible(store, principal, "clips", store.list_clips())


@router.get("/{clip_id}", response_model=ClipInfo, responses=responses(401, 404, 422))
def get_clip(clip_id: str, store: StoreDep, principal: PrincipalDep) -> ClipInfo:
    """One of your clips by id (or by the file name it was uploaded with)."""
    return clip_for(store, principal, clip_id)


@router.get(
    "/{clip_id}/bvh",
    response_class=Response,
    responses=responses(
        401,
        404,
        422,
        extra={200: {"description": "the uploaded file", "content": {"application/octet-stream": {}}}},
    ),
)
async def download_clip(
    clip_id: str,
    store: StoreDep,
    principal: PrincipalDep,
    read: Annotated[
        bool,
        Query(
            description="the motion as Segue read it, as gzip BVH text (a glTF clip's animation, a BVH "
            "that needed warnings read as it was read), instead of the bytes as uploaded"
        ),
    ] = False,
) -> Response:
    """The bytes of one of your clips as uploaded (BVH text, gzip-compressed BVH when it was
    uploaded so, or glTF), e.g. for a page to draw a leader beside the follower a job made for it;
    with ``read=true``, BVH a browser's reader takes as it is."""
    info = clip_for(store, principal, clip_id)
    data = await run_in_threadpool(store.clip_read_bytes if read else store.clip_bytes, info.id)
    return Response(
        data,
        media_type="application/octet-stream",
        headers={"Content-Disposition": f'attachment; filename="{info.id[:16]}-{_ascii(info.name)}"'},
    )


def _ascii(name: str) -> str:
    """A file name safe in a quoted header value."""
    return "".join(c if c.isascii() and c.isprintable() and c not in '"\\' else "_" for c in name)


@router.delete("/{clip_id}", **delete_route())
def delete_clip(clip_id: str, store: StoreDep, principal: PrincipalDep) -> Response:
    """Delete your clip (databases already built from it keep their data). The bytes go when no
    other principal holds the same clip."""
    return release(store, principal, "clips", clip_for(store, principal, clip_id).id, store.delete_clip)
