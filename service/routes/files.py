"""``/v1/files``: upload input files other than clips (e.g. a MIDI song), list and get them.

A synthesis request refers to an input file by the name it was uploaded with or by its id; the
job records the resolved id at submission (``inputs``), so later uploads do not change a job.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request, Response, status
from starlette.concurrency import run_in_threadpool

from schemas.files import FileInfo

from ..deps import PrincipalDep, SettingsDep, StoreDep
from ..errors import responses
from ..jsonbody import delete_route
from ..owners import file_for, hold, only_visible, release, seen
from ..uploads import receive_upload, stored, upload_body

router = APIRouter(prefix="/v1/files", tags=["files"])

_UPLOAD_BODY = upload_body(
    "Any input file (e.g. a standard MIDI file): as multipart field ``file``, or as the "
    "raw body with ``?name=``."
)


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=FileInfo,
    openapi_extra=_UPLOAD_BODY,
    responses=responses(
        400,
        401,
        413,
        422,
        503,
        extra={200: {"model": FileInfo, "description": "the same bytes were already uploaded"}},
    ),
)
async def upload_file(
    request: Request,
    response: Response,
    store: StoreDep,
    settings: SettingsDep,
    principal: PrincipalDep,
    name: Annotated[str | None, Query(max_length=255, description="file name (raw-body uploads)")] = None,
) -> FileInfo:
    """Upload an input file, stored once per content hash (201 new, 200 already there). Its content
    is checked by the engine that reads it, when a job runs."""
    async with receive_upload(request, settings.max_upload_bytes, name) as upload:
        existing = await run_in_threadpool(stored, store.file_info, upload.digest)
        if existing is None:
            existing = await run_in_threadpool(store.put_file, upload.name, upload.file)
        file = existing
        await run_in_threadpool(
            hold,
            store,
            principal,
            "files",
            file.id,
            response,
            upload.name,
            lambda: store.restore_file(file, upload.file),
        )
    return await run_in_threadpool(seen, store, principal, "files", file)


@router.get("", response_model=list[FileInfo], responses=responses(401))
def list_files(store: StoreDep, principal: PrincipalDep) -> list[FileInfo]:
    """Your uploaded files, oldest first."""
    return only_visible(store, principal, "files", store.list_files())


@router.get("/{file_id}", response_model=FileInfo, responses=responses(401, 404, 422))
def get_file(file_id: str, store: StoreDep, principal: PrincipalDep) -> FileInfo:
    """One of your files by id."""
    return file_for(store, principal, file_id)


@router.delete("/{file_id}", **delete_route())
def delete_file(file_id: str, store: StoreDep, principal: PrincipalDep) -> Response:
    """Delete your file (jobs already submitted with it fail if they still need it). The bytes go when
    no other principal holds the same file."""
    return release(store, principal, "files", file_for(store, principal, file_id).id, store.delete_file)
