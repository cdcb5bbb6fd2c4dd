"""Result downloads: a stored result motion in BVH, GLB, JSON frames or NPZ, streamed from the store.

Each download (result, format and options: :class:`workers.result_export.ExportSpec`) is made once
and kept in the store under its key. A small one (:func:`workers.result_export.inline_ok`, from the
result's array headers) is made here, a bounded number at once; anything larger, and every
retargeting onto a character, is a small job in a worker (:mod:`service.tasks`). Either way the
answer is streamed from the store in chunks, so the API's memory does not grow with the export.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from typing import BinaryIO

import anyio
from starlette.concurrency import run_in_threadpool
from starlette.responses import Response, StreamingResponse

from workers.backend import JobBackend
from workers.result_export import (
    MEDIA_TYPES,
    ExportFailure,
    ExportSpec,
    ExportTarget,
    ExportUnits,
    ResultFormat,
    ResultMesh,
    export_bytes,
    inline_ok,
    make_export,
    result_events,
)
from workers.store import NotFoundError, Store
from workers.tasks import task_payload

from .errors import ApiError
from .metrics import Metrics
from .tasks import TaskRunner

__all__ = [
    "MEDIA_TYPES",
    "ExportTarget",
    "ExportUnits",
    "ResultFormat",
    "ResultMesh",
    "export_bytes",
    "result_download",
    "result_events",
]

CHUNK_BYTES = 1 << 20
"""Bytes read from the store per chunk of a streamed download."""


def _chunks(fh: BinaryIO) -> Iterator[bytes]:
    try:
        while chunk := fh.read(CHUNK_BYTES):
            yield chunk
    finally:
        fh.close()


def _failure(exc: ExportFailure) -> ApiError:
    return ApiError(exc.status, exc.code, exc.message)


async def result_download(
    spec: ExportSpec,
    store: Store,
    backend: JobBackend,
    metrics: Metrics,
    runner: TaskRunner,
    limiter: anyio.CapacityLimiter,
    owner: str | None = None,
) -> Response:
    """The download ``spec`` asks for, streamed from the store (made first when it is not there, by
    ``owner``'s small job when a worker makes it)."""
    key = spec.key()
    try:
        fh = await run_in_threadpool(store.open_export, spec.job, key)
    except NotFoundError:
        frames, joints, fps = await run_in_threadpool(store.result_shape, spec.job, spec.result)
        if inline_ok(spec, frames, joints, fps):
            try:
                data = await anyio.to_thread.run_sync(make_export, store, spec, limiter=limiter)
            except ExportFailure as exc:
                raise _failure(exc) from None
            await run_in_threadpool(store.put_export, spec.job, key, data)
            return _response(spec, data)
        payload = task_payload("export", spec=spec.to_dict())
        await runner.run(f"export:{spec.job}:{key}", payload, store, backend, metrics, owner=owner)
        fh = await run_in_threadpool(store.open_export, spec.job, key)
    return StreamingResponse(_chunks(fh), media_type=MEDIA_TYPES[spec.format], headers=_headers(spec, fh))


def _headers(spec: ExportSpec, fh: BinaryIO | None = None) -> dict[str, str]:
    filename = f"segue-{spec.job}-{spec.result}.{spec.format.value}"
    headers = {"Content-Disposition": f'attachment; filename="{filename}"'}
    if fh is not None:
        with contextlib.suppress(OSError, ValueError, AttributeError):  # not a file: sent chunked
            headers["Content-Length"] = str(os.fstat(fh.fileno()).st_size)
    return headers


def _response(spec: ExportSpec, data: bytes) -> Response:
    return Response(data, media_type=MEDIA_TYPES[spec.format], headers=_headers(spec))
