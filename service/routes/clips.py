"""``/v1/clips``: upload BVH motions (plain or gzip), list, get and delete them."""

from __future__ import annotations

import hashlib
from typing import Annotated

from fastapi import APIRouter, Query, Request, Response, status
from starlette.concurrency import run_in_threadpool

from schemas import ClipInfo
from workers.store import NotFoundError

from ..deps import AuthDep, SettingsDep, StoreDep
from ..errors import responses
from ..uploads import read_upload, upload_body

router = APIRouter(prefix="/v1/clips", tags=["clips"])

_UPLOAD_BODY = upload_body(
    "A BVH file (``.bvh`` or gzip ``.bvh.gz``): as multipart field ``file``, or as the "
    "raw body with ``?name=``."
)


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=ClipInfo,
    dependencies=[AuthDep],
    openapi_extra=_UPLOAD_BODY,
    responses=responses(
        400,
        401,
        413,
        422,
        extra={200: {"model": ClipInfo, "description": "the same bytes were already uploaded"}},
    ),
)
async def upload_clip(
    request: Request,
    response: Response,
    store: StoreDep,
    settings: SettingsDep,
    name: Annotated[str | None, Query(max_length=255, description="file name (raw-body uploads)")] = None,
    units: Annotated[str | None, Query(description="declared length unit (default: guessed)")] = None,
) -> ClipInfo:
    """Upload a BVH clip; it is parsed and checked against the frame and joint limits.

    Stored once per content hash: 201 for a new clip, 200 when the same bytes exist.
    """
    file_name, data = await read_upload(request, settings.max_upload_bytes, name)
    digest = hashlib.sha256(data).hexdigest()
    try:
        existing = store.clip_info(digest)
    except NotFoundError:
        existing = None
    if existing is not None:
        response.status_code = status.HTTP_200_OK
        return existing
    return await run_in_threadpool(store.put_clip, file_name, data, settings.bvh_limits, units)


@router.get("", response_model=list[ClipInfo])
async def list_clips(store: StoreDep) -> list[ClipInfo]:
    """Every uploaded clip, oldest first."""
    return store.list_clips()


@router.get("/{clip_id}", response_model=ClipInfo, responses=responses(404, 422))
async def get_clip(clip_id: str, store: StoreDep) -> ClipInfo:
    """One clip by id (or by the file name it was uploaded with)."""
    return store.find_clip(clip_id)


@router.delete(
    "/{clip_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    dependencies=[AuthDep],
    responses=responses(401, 404, 422),
)
async def delete_clip(clip_id: str, store: StoreDep) -> Response:
    """Delete a clip (databases already built from it keep their data)."""
    store.delete_clip(clip_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
