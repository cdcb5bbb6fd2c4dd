"""Receiving uploads under a size limit: raw bodies and ``multipart/form-data`` with a ``file`` field;
checking a BVH upload.

The limit is enforced while reading (``Content-Length`` first, then the bytes actually received),
so an oversized upload is refused with 413 before it is held in memory. An upload is never held
whole in the API's memory: it is spooled as it arrives (:func:`receive_upload`: chunks of at most
:data:`CHUNK_BYTES` in memory, the rest in a temporary file under ``TMPDIR``; a multipart file part
is Starlette's own spooled file, the same 1 MiB), hashed on the way, and stored from that file in
chunks (:meth:`workers.objects.Objects.put_stream`). At most ``SEGUE_MAX_UPLOADS`` uploads are in
flight; one more is answered 503 ``too_many_uploads`` with ``Retry-After`` at once.

A BVH upload's header is checked here (:func:`motion.bvh_header.bvh_header`: joints, frames,
rate; a gzip file inflated in chunks and counted, never held), so what the header shows is
refused at once in bounded memory. A clip whose table is small (:data:`INLINE_VALUES` numbers) is
then parsed here; a larger one is parsed by a worker as a small job (:mod:`workers.tasks`), and
the answer waits for it: a 1 MB gzip file can hold 250 MB of text and 1.9M frames.
"""

from __future__ import annotations

import hashlib
import io
import tempfile
from collections.abc import AsyncGenerator, AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import PurePosixPath
from typing import Any, BinaryIO, TypeVar, cast

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

CHUNK_BYTES = 1 << 20
"""An upload is spooled and stored in chunks of this many bytes (held in memory at once)."""
RETRY_AFTER_S = 5
"""``Retry-After`` of a 503 ``too_many_uploads``."""
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


def checked_name(name: str, field: str) -> str:
    """The clip or file name an upload is stored under: ``name`` without its directories
    (``C:\\clips\\walk.bvh`` is ``walk.bvh``); 422 ``invalid_name`` naming ``field`` when it has
    control characters or leaves no name (``..``, ``.``, ``/``, blanks): a name that could not be
    used to find the upload again."""
    if any(not c.isprintable() for c in name):
        raise ApiError(
            422,
            "invalid_name",
            f"the {field} {name!r} has control characters; name the upload with printable characters",
            {"parameter": field},
        )
    base = PurePosixPath(name.replace("\\", "/")).name.strip()
    if base in ("", ".", ".."):
        raise ApiError(
            422,
            "invalid_name",
            f"the {field} {name!r} is not a file name (e.g. walk.bvh); '.', '..' and bare "
            "directories are refused",
            {"parameter": field},
        )
    return base[:255]


async def read_body(request: Request, limit: int) -> bytes:
    """The whole request body, refusing (413) more than ``limit`` bytes while reading (JSON bodies,
    which are small; uploads are spooled by :func:`receive_upload` instead)."""
    return b"".join([chunk async for chunk in _limited(request, limit)])


@dataclass
class Upload:
    """An upload spooled while it arrived: ``file`` holds it (in memory up to :data:`CHUNK_BYTES`,
    then in a temporary file on disk), ``size`` bytes with sha256 ``digest``, stored as ``name``."""

    name: str
    file: BinaryIO
    size: int
    digest: str

    @classmethod
    def from_bytes(cls, name: str, data: bytes) -> Upload:
        """An upload of ``data`` held in memory (tests, and callers that have the bytes already)."""
        return cls(name, io.BytesIO(data), len(data), hashlib.sha256(data).hexdigest())

    def read(self) -> bytes:
        """The whole upload (only for uploads of at most :data:`INLINE_UPLOAD_BYTES`)."""
        self.file.seek(0)
        return self.file.read()


class UploadSlots:
    """The uploads in flight (``SEGUE_MAX_UPLOADS``): one more is refused at once with 503
    ``too_many_uploads`` and ``Retry-After`` (not queued: a queued upload would hold its connection
    and its client's bytes while it waits). Used from the event loop's thread only."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.in_flight = 0

    def take(self) -> None:
        if self.in_flight >= self.limit:
            raise ApiError(
                503,
                "too_many_uploads",
                f"the server is receiving {self.in_flight} uploads, its limit (SEGUE_MAX_UPLOADS); "
                "try again shortly",
                {"max_uploads": self.limit},
                headers={"Retry-After": str(RETRY_AFTER_S)},
            )
        self.in_flight += 1

    def give(self) -> None:
        self.in_flight -= 1


def upload_slots(request: Request) -> UploadSlots:
    """The app's :class:`UploadSlots` (made on first use from its settings)."""
    slots: UploadSlots | None = getattr(request.app.state, "upload_slots", None)
    if slots is None:
        slots = UploadSlots(request.app.state.settings.max_uploads)
        request.app.state.upload_slots = slots
    return slots


def _digest(fh: BinaryIO) -> tuple[str, int]:
    """sha256 hex and size of an open file, read in chunks from its start (then rewound)."""
    fh.seek(0)
    hasher, size = hashlib.sha256(), 0
    for chunk in iter(lambda: fh.read(CHUNK_BYTES), b""):
        hasher.update(chunk)
        size += len(chunk)
    fh.seek(0)
    return hasher.hexdigest(), size


def _append(fh: BinaryIO, hasher: Any, chunk: bytes) -> None:
    fh.write(chunk)
    hasher.update(chunk)


@asynccontextmanager
async def receive_upload(request: Request, limit: int, name: str | None) -> AsyncIterator[Upload]:
    """The upload of this request, spooled (module docstring), while one of the app's
    :class:`UploadSlots` is held; its temporary file is removed at the end.

    A ``multipart/form-data`` body must carry the file in a field named ``file`` (its file name is
    the upload's name unless ``name`` is given); any other body is the file itself and ``name`` is
    required. Raises :class:`~service.errors.ApiError` (503 over ``SEGUE_MAX_UPLOADS``, 413 over
    ``limit``, 422 ``empty_upload`` for no bytes, 422 ``invalid_name``, 422 otherwise).
    """
    slots = upload_slots(request)
    slots.take()
    spool: BinaryIO | None = None
    try:
        content_type = request.headers.get("content-type", "")
        if name is not None:
            name = checked_name(name, "name")
        if content_type.startswith("multipart/form-data"):
            stream = _limited(request, limit, MULTIPART_OVERHEAD)
            try:
                form = await MultiPartParser(request.headers, stream, max_files=1, max_fields=8).parse()
            except MultiPartException as exc:
                raise ApiError(422, "invalid_request", f"invalid multipart upload: {exc.message}") from None
            upload = form.get("file")
            if not isinstance(upload, UploadFile):
                await form.close()
                raise ApiError(
                    422, "invalid_request", "a multipart upload needs the BVH file in a field named 'file'"
                )
            spool = upload.file  # starlette's spooled file: 1 MiB in memory, then disk
            if name is None and upload.filename:
                name = checked_name(upload.filename, "file name")
            digest, size = await anyio.to_thread.run_sync(_digest, spool)
        else:
            if not name:
                raise ApiError(
                    422,
                    "invalid_request",
                    "name the clip: POST the file as multipart field 'file', or the raw bytes with "
                    "?name=FILE.bvh",
                )
            spool = cast(BinaryIO, tempfile.SpooledTemporaryFile(max_size=CHUNK_BYTES))  # noqa: SIM115 (closed below)
            hasher, size, buffer = hashlib.sha256(), 0, bytearray()
            async for chunk in _limited(request, limit):
                buffer += chunk
                size += len(chunk)
                if len(buffer) >= CHUNK_BYTES:
                    await anyio.to_thread.run_sync(_append, spool, hasher, bytes(buffer))
                    buffer.clear()
            if buffer:
                await anyio.to_thread.run_sync(_append, spool, hasher, bytes(buffer))
            digest = hasher.hexdigest()
        if size > limit:
            raise too_large(limit)
        if size == 0:
            raise ApiError(
                422,
                "empty_upload",
                f"the upload {clean_name(name or '')!r} is empty (0 bytes); send the file's contents "
                "(curl: --data-binary @FILE, or -F file=@FILE)",
            )
        spool.seek(0)
        yield Upload(name or "upload.bvh", spool, size, digest)
    finally:
        slots.give()
        if spool is not None:
            await anyio.to_thread.run_sync(spool.close)


def stored(info_of: Callable[[str], Info], digest: str) -> Info | None:
    """What the store holds under the content address ``digest`` (``info_of`` is the store's
    ``clip_info`` or ``file_info``), or None when these bytes are new."""
    try:
        return info_of(digest)
    except NotFoundError:
        return None


def upload_body(description: str) -> dict[str, Any]:
    """OpenAPI ``requestBody`` of an upload route (:func:`receive_upload`): a multipart field ``file``
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
INLINE_UPLOAD_BYTES = 8 << 20
"""Largest clip upload read into the API's memory (its header checked, a small one parsed there);
a larger one goes from its spooled file to the staging area in chunks, and a worker parses it."""


async def parse_upload(
    upload: Upload,
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
    fault, as :func:`motion.io.parse_motion` words it. An upload over :data:`INLINE_UPLOAD_BYTES`
    is streamed to the staging area and parsed by a worker (``owner``'s small job), never read
    whole here."""
    file_name = upload.name
    source: bytes | BinaryIO = upload.file
    if upload.size <= INLINE_UPLOAD_BYTES:
        data = await anyio.to_thread.run_sync(upload.read, limiter=limiter)
        if is_gltf(data):
            inline = len(data) <= INLINE_GLTF_BYTES
        else:
            head = await anyio.to_thread.run_sync(bvh_header, data, limits, file_name, limiter=limiter)
            inline = head.frames_bound * head.channels <= INLINE_VALUES
        if inline:
            return await anyio.to_thread.run_sync(
                store.put_clip, file_name, data, limits, units, limiter=limiter
            )
        source = data
    digest = upload.digest
    staged = await run_in_threadpool(store.stage, source)
    del source
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
