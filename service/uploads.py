"""Reading uploads under a size limit: raw bodies and ``multipart/form-data`` with a ``file`` field;
checking a BVH upload.

The limit is enforced while reading (``Content-Length`` first, then the bytes actually received),
so an oversized upload is refused with 413 before it is held in memory.

A BVH upload's header is checked here (:func:`motion.bvh_header.bvh_header`: joints, frames,
rate; a gzip file inflated in chunks and counted, never held), so what the header shows is
refused at once in bounded memory. A clip whose table is small (:data:`INLINE_VALUES` numbers) is
then parsed here; a larger one is parsed by a worker as a small job (:mod:`workers.tasks`), and
the answer waits for it: a 1 MB gzip file can hold 250 MB of text and 1.9M frames.
"""

from __future__ import annotations

import hashlib
from collections.abc import AsyncGenerator, Callable
from pathlib import PurePosixPath
from typing import Any, TypeVar

import anyio
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import UploadFile
from starlette.formparsers import MultiPartException, MultiPartParser
from starlette.requests import Request

from motion import BvhLimits
from motion.bvh_header import bvh_header
from motion.gltf import is_gltf
from schemas import ClipInfo
from workers.backend import JobBackend
from workers.store import NotFoundError, Store
from workers.tasks import task_payload

from .errors import ApiError, too_large
from .metrics import Metrics
from .tasks import TaskRunner

Info = TypeVar("Info")

MULTIPART_OVERHEAD = 64 * 1024
"""Room for the multipart envelope (boundaries, part headers, small fields) above the file limit."""


async def _limited(request: Request, limit: int, overhead: int = 0) -> AsyncGenerator[bytes, None]:
    """The body's chunks; 413 (naming ``limit``) once more than ``limit + overhead`` bytes arrive."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit + overhead:
        raise too_large(limit)
    total = 0
    async for chunk in request.stream():
        total += len(chunk)
        if total > limit + overhead:
            raise too_large(limit)
        yield chunk


def clean_name(name: str) -> str:
    """A file name without directories or control characters (``"upload.bvh"`` when nothing is left)."""
    base = PurePosixPath(name.replace("\\", "/")).name
    base = "".join(c for c in base if c.isprintable()).strip()
    return base[:255] or "upload.bvh"


async def read_body(request: Request, limit: int) -> bytes:
    """The whole request body, refusing (413) more than ``limit`` bytes while reading."""
    return b"".join([chunk async for chunk in _limited(request, limit)])


async def read_upload(request: Request, limit: int, name: str | None) -> tuple[str, bytes]:
    """The uploaded file's name and bytes.

    A ``multipart/form-data`` body must carry the file in a field named ``file`` (its file name is
    the clip's name unless ``name`` is given); any other body is the file itself and ``name`` is
    required. Raises :class:`~service.errors.ApiError` (413 over ``limit``, 422 ``empty_upload`` for no
    bytes, 422 otherwise).
    """
    content_type = request.headers.get("content-type", "")
    if content_type.startswith("multipart/form-data"):
        stream = _limited(request, limit, MULTIPART_OVERHEAD)
        try:
            form = await MultiPartParser(request.headers, stream, max_files=1, max_fields=8).parse()
        except MultiPartException as exc:
            raise ApiError(422, "invalid_request", f"invalid multipart upload: {exc.message}") from None
        upload = form.get("file")
        if not isinstance(upload, UploadFile):
            raise ApiError(
                422, "invalid_request", "a multipart upload needs the BVH file in a field named 'file'"
            )
        if upload.size is not None and upload.size > limit:
            raise too_large(limit)
        data = await upload.read()
        await upload.close()
        if len(data) > limit:
            raise too_large(limit)
        return clean_name(name or upload.filename or ""), _not_empty(data, name or upload.filename)
    if not name:
        raise ApiError(
            422,
            "invalid_request",
            "name the clip: POST the file as multipart field 'file', or the raw bytes with ?name=FILE.bvh",
        )
    return clean_name(name), _not_empty(await read_body(request, limit), name)


def _not_empty(data: bytes, name: str | None) -> bytes:
    """``data``, or 422 ``empty_upload`` when there are no bytes (nothing to store or parse)."""
    if not data:
        raise ApiError(
            422,
            "empty_upload",
            f"the upload {clean_name(name or '')!r} is empty (0 bytes); send the file's contents "
            "(curl: --data-binary @FILE, or -F file=@FILE)",
        )
    return data


def stored(info_of: Callable[[str], Info], data: bytes) -> Info | None:
    """What the store holds under the content address of ``data`` (``info_of`` is the store's
    ``clip_info`` or ``file_info``), or None when these bytes are new."""
    try:
        return info_of(hashlib.sha256(data).hexdigest())
    except NotFoundError:
        return None


def upload_body(description: str) -> dict[str, Any]:
    """OpenAPI ``requestBody`` of an upload route (:func:`read_upload`): a multipart field ``file``
    or the raw body with ``?name=``."""
    return {
        "requestBody": {
            "required": True,
            "description": description,
            "content": {
                "multipart/form-data": {
                    "schema": {
                        "type": "object",
                        "required": ["file"],
                        "properties": {"file": {"type": "string", "format": "binary"}},
                    }
                },
                "application/octet-stream": {"schema": {"type": "string", "format": "binary"}},
            },
        }
    }


INLINE_VALUES = 2_000_000
"""Most numbers (frames x channels) of a BVH table parsed in the API process (~16 MB of float64,
a few tens of milliseconds); larger tables are parsed by a worker (0: every clip). The bound is
the larger of the ``Frames:`` line and the lines present (which win when they differ)."""
INLINE_GLTF_BYTES = 4 << 20
"""Largest glTF/GLB upload read in the API process; larger ones are read by a worker."""


async def parse_upload(
    file_name: str,
    data: bytes,
    units: str | None,
    limits: BvhLimits,
    store: Store,
    backend: JobBackend,
    metrics: Metrics,
    runner: TaskRunner,
    limiter: anyio.CapacityLimiter,
    owner: str | None = None,
) -> ClipInfo:
    """Check and store a new BVH or glTF upload (module docstring): 400 ``invalid_bvh`` naming the
    fault, as :func:`motion.io.parse_motion` words it. A worker's parse is ``owner``'s small job."""
    if is_gltf(data):
        inline = len(data) <= INLINE_GLTF_BYTES
    else:
        head = await anyio.to_thread.run_sync(bvh_header, data, limits, file_name, limiter=limiter)
        inline = head.frames_bound * head.channels <= INLINE_VALUES
    if inline:
        return await anyio.to_thread.run_sync(store.put_clip, file_name, data, limits, units, limiter=limiter)
    digest = hashlib.sha256(data).hexdigest()
    staged = await run_in_threadpool(store.stage, data)
    payload = task_payload(
        "clip",
        staged=staged,
        digest=digest,
        name=file_name,
        units=units,
        limits=[limits.max_joints, limits.max_frames, limits.max_bytes, limits.max_joint_frames],
    )
    keep = False  # whether a small job may still read the staged bytes (it removes them when it ends)
    try:
        key = f"clip:{digest}:{units}:{file_name}"
        done = await runner.run(key, payload, store, backend, metrics, owner=owner)
    except ApiError as exc:
        keep = exc.code == "task_pending"
        raise
    except BaseException:  # the request was cancelled (the client left): the small job goes on
        keep = True
        raise
    finally:
        if not keep:  # answered, failed or refused: no job reads them any more
            await run_in_threadpool(store.delete_staged, staged)
    return ClipInfo.model_validate(done["clip"])
