"""The durable store: clips, files, databases, jobs, events and results, in one object store.

The objects live in a local directory (the default) or an S3-compatible bucket
(:mod:`workers.objects`, chosen by ``SEGUE_STORE_URL``); this class keeps the names and formats.
Keys::

    clips/<sha256>.bvh            uploaded bytes (as uploaded: BVH, possibly gzip, or glTF/GLB)
    clips/<sha256>.read.bvh.gz    the motion as read, as BVH (gzip), for a clip whose file a
                                  browser cannot read as it is: glTF, or a BVH that needed warnings
    clips/<sha256>.json           ClipInfo
    clips/<sha256>.owners         the principals holding the clip, each with its own record (name,
                                  upload time, build job; :mod:`workers.holders`; likewise files/,
                                  databases/<id>/owners): content-addressed things are shared, each
                                  holder sees its own name and deletes only its own hold
    files/<sha256>.bin|.json      other uploads (MIDI, audio) and their FileInfo
    databases/<id>/spec.json      the validated spec (clip references resolved to ids)
    databases/<id>/info.json      DatabaseInfo
    databases/<id>/arrays.json    manifest of the arrays (:mod:`engines.container`), written last
    databases/<id>/arrays/*.npy   motion library + kind-specific arrays, one uncompressed .npy each
    databases/<id>/data.npz       the same arrays as written before (read, and converted once)
    jobs/<id>/request.json        {"kind", "payload"}
    jobs/<id>/info.json           JobInfo
    jobs/<id>/events.jsonl        the job's events (the backends' archive), written whole at its end
    jobs/<id>/events/<n>.jsonl    batches of a running job's events from event n on (Redis backend:
                                  written as they are published, removed once events.jsonl is)
    jobs/<id>/results/<rid>.npz   result motion (motion.serialize arrays)
    jobs/<id>/results/<rid>.json  Report
    jobs/<id>/exports/<name>      derived bytes of a result (exports), by whoever makes them

Every write replaces an object whole (atomically: a crash or a concurrent reader never sees half an
object), and nothing already stored is changed by a failed request.

A process's own disk is a cache only: an engine memory-maps a database from
:meth:`Store.database_dir`, which for a local store is the database's own directory and for an
object store a copy downloaded once into the process's cache directory, evicted by bytes
(:class:`workers.dbcache.DiskCache`).
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, BinaryIO, Literal

import numpy as np

from engines.base import container
from motion import Motion, MotionError
from motion.bvh import BvhLimits, detect_units
from motion.errors import ReadWarning
from motion.io import parse_motion
from motion.serialize import motion_from_arrays, motion_to_arrays
from schemas import ClipInfo, DatabaseInfo, JobInfo, Report
from schemas.clips import AnimationInfo
from schemas.files import FileInfo

from . import holders as holding
from .dbcache import DiskCache, ObjectCache
from .objects import LocalObjects, ObjectNotFound, Objects, atomic_write, open_objects

Arrays = dict[str, Any]
Owned = Literal["clips", "files", "databases"]
Visible = Callable[[str], bool]
"""``visible(id)``: may the caller see the clip, file or database with this id (ownership filter)."""

LEGACY_NPZ = "data.npz"
READ_SUFFIX = ".read.bvh.gz"
"""A clip's motion as read (BVH text, gzip), beside its uploaded bytes: ``clips/<id>.read.bvh.gz``."""
DEFAULT_DISK_CACHE_BYTES = 8 << 30


class NotFoundError(LookupError):
    """A clip, database, job or result that does not exist."""


def now() -> datetime:
    return datetime.now(UTC)


def _atomic_write(path: Path, data: bytes) -> None:
    atomic_write(path, data)


def npz_bytes(arrays: Mapping[str, Any]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def load_npz(data: bytes) -> dict[str, np.ndarray]:
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _media_type(data: bytes) -> str:
    from engines.registry import recording_media_type

    if data[:4] == b"MThd":
        return "audio/midi"
    audio = recording_media_type(data[:16])
    if audio is not None:
        return audio
    if data[:9].upper().startswith(b"HIERARCHY") or data[:2] == b"\x1f\x8b":
        return "application/x-bvh"
    return "application/octet-stream"


Source = bytes | BinaryIO
"""Bytes to store: in memory, or an open file (an upload spooled to disk) stored in chunks."""


def source_facts(source: Source) -> tuple[str, int, bytes]:
    """``(sha256 hex, size, first 16 bytes)`` of ``source`` (a file is read from its start in
    chunks, then rewound)."""
    if isinstance(source, bytes):
        return hashlib.sha256(source).hexdigest(), len(source), source[:16]
    source.seek(0)
    hasher, size, head = hashlib.sha256(), 0, b""
    for chunk in iter(lambda: source.read(1 << 20), b""):
        if not head:
            head = chunk[:16]
        hasher.update(chunk)
        size += len(chunk)
    source.seek(0)
    return hasher.hexdigest(), size, head


def _safe_id(value: str) -> str:
    if not value or any(c not in "0123456789abcdefghijklmnopqrstuvwxyz-_" for c in value) or len(value) > 80:
        raise NotFoundError(f"no such id {value!r}")
    return value


def _seekable(fh: BinaryIO) -> bool:
    seekable = getattr(fh, "seekable", None)
    return bool(seekable()) if callable(seekable) else False


class Store:
    """Clips, files, databases, jobs and results in one object store (see the module docstring).

    ``location`` is a directory, a store URL (``s3://bucket/prefix``) or an :class:`Objects`
    backend. ``cache_dir`` is this process's local cache of databases for an object store (default:
    ``./segue-data``); a local store needs none (its files are mapped in place).
    ``disk_cache_bytes`` bounds that cache; ``object_cache`` (the Redis database cache) sits
    between the object store and the disk cache when given.
    """

    def __init__(
        self,
        location: str | Path | Objects,
        cache_dir: str | Path | None = None,
        *,
        disk_cache_bytes: int = DEFAULT_DISK_CACHE_BYTES,
        object_cache: ObjectCache | None = None,
    ) -> None:
        self.objects: Objects = open_objects(location) if isinstance(location, str | Path) else location
        self.url = self.objects.url
        local = self.objects.local_path("clips")
        self.local = local is not None
        self.root = (
            Path(self.url) if isinstance(self.objects, LocalObjects) else Path(cache_dir or "segue-data")
        )
        """The local directory this process uses: the store itself when local, else its cache."""
        self.cache = DiskCache(self.root / "cache" / "databases", disk_cache_bytes)
        self.object_cache = object_cache
        self._infos: dict[str, bytes] = {}  # immutable info objects (clips, files) by key
        self._lock = threading.Lock()

    @classmethod
    def from_settings(cls, settings: Any, object_cache: ObjectCache | None = None) -> Store:
        """The store a :class:`~workers.settings.Settings` names (``store_url``, default ``data_dir``)."""
        return cls(
            settings.store_url or settings.data_dir,
            settings.data_dir,
            disk_cache_bytes=settings.disk_cache_mb << 20,
            object_cache=object_cache,
        )

    # -- small helpers ------------------------------------------------------------------------
    def _get(self, key: str, missing: str) -> bytes:
        try:
            return self.objects.get(key)
        except ObjectNotFound:
            raise NotFoundError(missing) from None

    def _immutable(self, key: str, missing: str) -> bytes:
        """An object that never changes once written (clip and file infos), kept in memory."""
        with self._lock:
            data = self._infos.get(key)
        if data is None:
            data = self._get(key, missing)
            with self._lock:
                if len(self._infos) > 100_000:
                    self._infos.clear()
                self._infos[key] = data
        return data

    def _write(self, key: str, source: Source) -> None:
        """Store ``source`` under ``key``: bytes at once, a file streamed from its start."""
        if isinstance(source, bytes):
            self.objects.put(key, source)
            return
        source.seek(0)
        self.objects.put_stream(key, source)

    def _forget(self, key: str) -> None:
        with self._lock:
            self._infos.pop(key, None)

    def check_id(self, item_id: str) -> str:
        """``item_id`` when it is a valid clip, database or job id, else :class:`NotFoundError`."""
        return _safe_id(item_id)

    # -- clips --------------------------------------------------------------------------------
    def put_clip(
        self, name: str, data: bytes, limits: BvhLimits | None = None, units: str | None = None
    ) -> ClipInfo:
        """Validate and store an uploaded clip (BVH, or a glTF file's first animation); the same
        bytes are stored once (content address). The info carries the reader's warnings (what the
        file needed to be read) and a glTF file's animations.

        Raises :class:`motion.MotionError` (a ``BvhError`` for BVH) for invalid content; nothing
        is written then.
        """
        digest = hashlib.sha256(data).hexdigest()
        key = f"clips/{digest}.json"
        try:
            return ClipInfo.model_validate_json(self.objects.get(key))
        except ObjectNotFound:
            pass
        notes: list[ReadWarning] = []
        motion = parse_motion(data, units=units, limits=limits, source=name, name=name, warnings=notes)
        guess = detect_units(motion)
        animations: list[AnimationInfo] = []
        from motion.gltf import gltf_animations, is_gltf

        if is_gltf(data):
            found = gltf_animations(data, source=name)
            animations = [AnimationInfo(name=a.name, frames=a.frames, fps=a.fps) for a in found]
        info = ClipInfo(
            id=digest,
            name=name,
            frames=motion.num_frames,
            fps=motion.fps,
            joints=list(motion.skeleton.names),
            units=motion.units,
            height_m=round(guess.height * motion.metres_per_unit, 4),
            size_bytes=len(data),
            created_at=now(),
            format="gltf" if animations else "bvh",
            animations=animations,
            warnings=[w.message for w in notes],
        )
        if animations or notes:
            from motion.bvh import bvh_text

            text = bvh_text(motion).encode()
            self.objects.put(f"clips/{digest}{READ_SUFFIX}", gzip.compress(text, 6, mtime=0))
        self.objects.put(f"clips/{digest}.bvh", data)
        if not self.objects.put(key, info.model_dump_json().encode(), if_absent=True):
            return ClipInfo.model_validate_json(self.objects.get(key))  # a concurrent upload won
        return info

    def restore_clip(self, info: ClipInfo, data: Source) -> None:
        """Write a clip's bytes and info back (an upload whose bytes another holder deleted)."""
        self._write(f"clips/{info.id}.bvh", data)
        self.objects.put(f"clips/{info.id}.json", info.model_dump_json().encode())

    def clip_info(self, clip_id: str) -> ClipInfo:
        key = f"clips/{_safe_id(clip_id)}.json"
        return ClipInfo.model_validate_json(self._immutable(key, f"no clip {clip_id!r}"))

    def clip_bytes(self, clip_id: str) -> bytes:
        return self._get(f"clips/{_safe_id(clip_id)}.bvh", f"no clip {clip_id!r}")

    def clip_read_bytes(self, clip_id: str) -> bytes:
        """The clip's motion as read, as gzip BVH text, for a clip kept so (glTF, or a BVH that
        needed warnings); the uploaded bytes for any other clip (:class:`NotFoundError` when a
        kept copy is gone: its bytes were restored after another holder's delete)."""
        info = self.clip_info(clip_id)
        if info.format == "bvh" and not info.warnings:
            return self.clip_bytes(info.id)
        return self._get(f"clips/{info.id}{READ_SUFFIX}", f"no readable copy of clip {clip_id!r}")

    def _infos_under(self, kind: str) -> list[bytes]:
        out = []
        for name in self.objects.children(kind):
            key = f"{kind}/{name}"
            if name.endswith(".json"):
                try:
                    out.append(self._immutable(key, key))
                except NotFoundError:  # deleted since the listing
                    continue
        return out

    def list_clips(self) -> list[ClipInfo]:
        infos = [ClipInfo.model_validate_json(b) for b in self._infos_under("clips")]
        return sorted(infos, key=lambda c: c.created_at)

    def find_clip(self, ref: str, visible: Visible | None = None) -> ClipInfo:
        """A clip by id, or by the file name it was uploaded with (the newest such upload), among
        the clips ``visible`` accepts (default: all)."""
        try:
            info = self.clip_info(ref)
            if visible is None or visible(info.id):
                return info
        except NotFoundError:
            pass
        matches = [
            c
            for c in self.list_clips()
            if (c.name == ref or c.name.removesuffix(".gz") == ref) and (visible is None or visible(c.id))
        ]
        if not matches:
            raise NotFoundError(f"no uploaded clip named {ref!r}; upload it first (POST /v1/clips)")
        return matches[-1]

    def delete_clip(self, clip_id: str) -> None:
        info = self.clip_info(clip_id)
        for suffix in (".json", ".bvh", READ_SUFFIX, ".owners"):
            self.objects.delete(f"clips/{info.id}{suffix}")
        self._forget(f"clips/{info.id}.json")

    # -- holders of content-addressed things ----------------------------------------------------
    def _owners_key(self, kind: Owned, item_id: str) -> str:
        if kind == "databases":
            return f"databases/{_safe_id(item_id)}/owners"
        return f"{kind}/{_safe_id(item_id)}.owners"

    def owners(self, kind: Owned, item_id: str) -> set[str]:
        """The principals holding a clip, file or database (empty: recorded before owners were, or
        being deleted)."""
        return set(self.holders(kind, item_id))

    def holders(self, kind: Owned, item_id: str) -> dict[str, holding.Record]:
        """Each holder's own record (:mod:`workers.holders`: ``name``, ``created_at``,
        ``build_job``; empty for holds recorded before records were)."""
        current = holding.read(self.objects, self._owners_key(kind, item_id))
        return {} if current.deleting else current.holders

    def add_owner(
        self,
        kind: Owned,
        item_id: str,
        principal: str,
        record: Mapping[str, Any] | None = None,
        restore: Callable[[], None] | None = None,
        replace: bool = False,
    ) -> bool:
        """Record ``principal`` as a holder with its own ``record`` (JSON values; an earlier record
        is kept unless ``replace``); False when it held it already. ``restore`` writes the bytes
        back when another holder's delete removed them meanwhile (an upload has them in hand);
        atomic against :meth:`release`."""
        base = self._owners_key(kind, item_id).removesuffix(".owners").removesuffix("/owners")
        stored = {"clips": (".json", ".bvh"), "files": (".json", ".bin"), "databases": ("/info.json",)}
        return holding.hold(
            self.objects,
            self._owners_key(kind, item_id),
            principal,
            dict(record or {}),
            lambda: all(self.objects.exists(base + suffix) for suffix in stored[kind]),
            restore,
            replace,
        )

    def release(
        self, kind: Owned, item_id: str, principal: str, delete: Callable[[str], None], force: bool = False
    ) -> bool:
        """Drop ``principal``'s hold and ``delete(item_id)`` the thing when no other principal
        holds it (or ``force``), atomically against :meth:`add_owner`. True when deleted."""
        return holding.release(
            self.objects, self._owners_key(kind, item_id), principal, lambda: delete(item_id), force
        )

    # -- databases ----------------------------------------------------------------------------
    def _db(self, db_id: str) -> str:
        return f"databases/{_safe_id(db_id)}"

    def put_database_info(self, info: DatabaseInfo, spec: dict[str, Any] | None = None) -> None:
        d = self._db(info.id)
        if spec is not None:
            self.objects.put(f"{d}/spec.json", json.dumps(spec, sort_keys=True).encode())
        self.objects.put(f"{d}/info.json", info.model_dump_json().encode())

    def database_info(self, db_id: str) -> DatabaseInfo:
        data = self._get(f"{self._db(db_id)}/info.json", f"no database {db_id!r}")
        return DatabaseInfo.model_validate_json(data)

    def database_spec(self, db_id: str) -> dict[str, Any]:
        return dict(json.loads(self._get(f"{self._db(db_id)}/spec.json", f"no database {db_id!r}")))

    def list_databases(self) -> list[DatabaseInfo]:
        out = []
        for db_id in self.objects.children("databases"):
            try:
                out.append(DatabaseInfo.model_validate_json(self.objects.get(f"databases/{db_id}/info.json")))
            except (ObjectNotFound, ValueError):  # being written or deleted, or not an id
                continue
        return sorted(out, key=lambda i: i.created_at)

    def put_database_arrays(self, db_id: str, arrays: Mapping[str, Any] | bytes) -> None:
        """Store a database's arrays (a mapping, or the bytes of an ``.npz`` of them): one ``.npy``
        object each, then the manifest (the commit point: readers never see a partial set)."""
        d = self._db(db_id)
        if isinstance(arrays, bytes | bytearray | memoryview):
            try:
                arrays = load_npz(bytes(arrays))
            except (ValueError, OSError) as exc:
                raise ValueError(f"database {db_id!r}: not an .npz of arrays ({exc})") from None
        manifest, files = container.pack(arrays)
        for file, data in files:
            self.objects.put(f"{d}/{container.ARRAYS_DIR}/{file}", data)
        self.objects.put(f"{d}/{container.MANIFEST}", manifest.to_bytes())

    def database_manifest(self, db_id: str) -> container.Manifest:
        """The manifest of a database's arrays, converting a database stored as ``data.npz``
        (before arrays were stored one per object) on first use. Raises :class:`NotFoundError`."""
        d = self._db(db_id)
        try:
            return container.Manifest.from_bytes(self.objects.get(f"{d}/{container.MANIFEST}"))
        except ObjectNotFound:
            pass
        try:
            legacy = self.objects.get(f"{d}/{LEGACY_NPZ}")
        except ObjectNotFound:
            raise NotFoundError(f"database {db_id!r} has no built data") from None
        self.put_database_arrays(db_id, legacy)  # the .npz stays: an upgrade loses nothing
        return container.Manifest.from_bytes(self.objects.get(f"{d}/{container.MANIFEST}"))

    def has_database_arrays(self, db_id: str) -> bool:
        """True when the database's arrays are stored (in either layout)."""
        d = self._db(db_id)
        return self.objects.exists(f"{d}/{container.MANIFEST}") or self.objects.exists(f"{d}/{LEGACY_NPZ}")

    def database_dir(self, db_id: str) -> Path:
        """A local directory holding the database's arrays (:mod:`engines.container`) for
        memory-mapping: the store's own directory when local, else this process's cached copy
        (downloaded on first use, through the object cache when there is one)."""
        manifest = self.database_manifest(db_id)
        d = self._db(db_id)
        own = self.objects.local_path(d)
        if own is not None:
            return own
        return self.cache.fetch(db_id, manifest, lambda file, path: self._fetch(f"{d}/{file}", path))

    def _fetch(self, key: str, path: Path) -> None:
        if self.object_cache is not None:
            data = self.object_cache.get(key)
            if data is not None:
                atomic_write(path, data)
                return
        size = self.objects.download(key, path)
        if self.object_cache is not None and self.object_cache.wants(size):
            self.object_cache.put(key, path.read_bytes())

    def database_arrays(self, db_id: str) -> dict[str, np.ndarray]:
        """Every array of a database, large ones memory-mapped from :meth:`database_dir`."""
        return container.load_all(self.database_dir(db_id))

    @contextmanager
    def open_database(self, db_id: str) -> Iterator[Mapping[str, np.ndarray]]:
        """A database's arrays, each read when first indexed: mapped from the store's files when
        local, fetched one object each from an object store (nothing written to local disk), so a
        query reading a few small arrays costs those."""
        manifest = self.database_manifest(db_id)
        d = self._db(db_id)
        own = self.objects.local_path(d)
        if own is not None:
            yield container.open_arrays(own)
            return
        cached = self.cache.path_if_cached(db_id)
        if cached is not None:
            yield container.open_arrays(cached)
            return

        def load(name: str) -> np.ndarray:
            key = f"{d}/{container.ARRAYS_DIR}/{manifest.files[name]}"
            return container.array_from_npy(self._get(key, f"database {db_id!r} lost array {name!r}"))

        yield container.LazyArrays(manifest, load)

    def database_arrays_bytes(self, db_id: str) -> bytes:
        """The database's arrays as the bytes of one ``.npz`` (for exports and tools that want a
        single file; engines map :meth:`database_dir` instead)."""
        with self.open_database(db_id) as arrays:
            return npz_bytes({name: arrays[name] for name in arrays})

    def delete_database(self, db_id: str) -> None:
        """Remove a database's objects, its owners object last (:func:`workers.holders.release`: on
        an object store that object holds the delete's marker, which a concurrent re-post of the
        spec waits on; a local directory is removed at once under the holders' lock)."""
        d = self._db(db_id)
        keys = self.objects.list(d)
        if not keys:
            raise NotFoundError(f"no database {db_id!r}")
        if self.objects.local_path(d) is not None:
            self.objects.delete_prefix(d)
        else:
            owners = self._owners_key("databases", db_id)
            for key in keys:
                if key != owners:
                    self.objects.delete(key)
            self.objects.delete(owners)
        self.cache.evict(db_id)

    # -- other input files (MIDI...) ------------------------------------------------------------
    def put_file(self, name: str, data: Source) -> FileInfo:
        """Store an uploaded input file once per content hash (no parsing: engines validate it);
        ``data`` may be an open file, stored in chunks (never read whole)."""
        digest, size, head = source_facts(data)
        key = f"files/{digest}.json"
        try:
            return FileInfo.model_validate_json(self.objects.get(key))
        except ObjectNotFound:
            pass
        info = FileInfo(id=digest, name=name, size_bytes=size, media_type=_media_type(head), created_at=now())
        self._write(f"files/{digest}.bin", data)
        if not self.objects.put(key, info.model_dump_json().encode(), if_absent=True):
            return FileInfo.model_validate_json(self.objects.get(key))  # a concurrent upload won
        return info

    def delete_file(self, file_id: str) -> None:
        info = self.file_info(file_id)
        for suffix in (".json", ".bin", ".owners"):
            self.objects.delete(f"files/{info.id}{suffix}")
        self._forget(f"files/{info.id}.json")

    def restore_file(self, info: FileInfo, data: Source) -> None:
        """Write a file's bytes and info back (an upload whose bytes another holder deleted)."""
        self._write(f"files/{info.id}.bin", data)
        self.objects.put(f"files/{info.id}.json", info.model_dump_json().encode())

    def file_info(self, file_id: str) -> FileInfo:
        key = f"files/{_safe_id(file_id)}.json"
        return FileInfo.model_validate_json(self._immutable(key, f"no file {file_id!r}"))

    def file_bytes(self, file_id: str) -> bytes:
        return self._get(f"files/{_safe_id(file_id)}.bin", f"no file {file_id!r}")

    def list_files(self) -> list[FileInfo]:
        infos = [FileInfo.model_validate_json(b) for b in self._infos_under("files")]
        return sorted(infos, key=lambda f: f.created_at)

    def input_bytes(self, upload_id: str) -> bytes:
        """The bytes of an uploaded clip or file by id."""
        try:
            return self.clip_bytes(upload_id)
        except NotFoundError:
            return self.file_bytes(upload_id)

    def find_input(self, ref: str, visible: Visible | None = None, holder: str | None = None) -> str:
        """Resolve a request's input reference to an upload id: a clip or file id, or the name of an
        uploaded clip or file (the newest upload of that name), among those ``visible`` accepts.
        With ``holder``, names and upload times are that principal's own (its holder records),
        the shared ones where it has none."""
        ok = visible or (lambda _id: True)
        for lookup in (self.clip_info, self.file_info):
            try:
                found = lookup(ref).id
            except NotFoundError:
                continue
            if ok(found):
                return found
        base = ref.replace("\\", "/").rsplit("/", 1)[-1]
        named: list[tuple[datetime, str]] = []
        kinds: tuple[tuple[Owned, list[ClipInfo] | list[FileInfo]], ...] = (
            ("clips", self.list_clips()),
            ("files", self.list_files()),
        )
        for kind, infos in kinds:
            for info in infos:
                if not ok(info.id):
                    continue
                own = self.holders(kind, info.id).get(holder, {}) if holder is not None else {}
                name = str(own.get("name") or info.name)
                created = (
                    datetime.fromisoformat(own["created_at"]) if own.get("created_at") else info.created_at
                )
                if name in (ref, base) or (kind == "clips" and name.removesuffix(".gz") in (ref, base)):
                    named.append((created, info.id))
        if not named:
            raise NotFoundError(
                f"no uploaded clip or file named {ref!r}; upload it first (POST /v1/clips for BVH, "
                "POST /v1/files for other files)"
            )
        return max(named)[1]

    # -- jobs and results -----------------------------------------------------------------------
    def _job(self, job_id: str) -> str:
        return f"jobs/{_safe_id(job_id)}"

    def put_job(self, info: JobInfo, request: dict[str, Any] | None = None) -> None:
        d = self._job(info.id)
        if request is not None:
            self.objects.put(f"{d}/request.json", json.dumps(request).encode())
        self.objects.put(f"{d}/info.json", info.model_dump_json().encode())

    def job_info(self, job_id: str) -> JobInfo:
        return JobInfo.model_validate_json(self._get(f"{self._job(job_id)}/info.json", f"no job {job_id!r}"))

    def list_jobs(self) -> list[JobInfo]:
        """Every job, oldest first."""
        out = []
        for job_id in self.objects.children("jobs"):
            try:
                out.append(JobInfo.model_validate_json(self.objects.get(f"jobs/{job_id}/info.json")))
            except (ObjectNotFound, ValueError):  # being written or deleted, or not an id
                continue
        return sorted(out, key=lambda i: i.created_at)

    def delete_job(self, job_id: str) -> None:
        """Remove a job's record, request, events and results (NotFoundError when there is none)."""
        d = self._job(job_id)
        if not self.objects.exists(f"{d}/info.json"):
            raise NotFoundError(f"no job {job_id!r}")
        self.objects.delete_prefix(d)

    def discard_job(self, job_id: str) -> None:
        """Remove whatever a job left (a submission the backend refused), without checks."""
        self.objects.delete_prefix(self._job(job_id))

    def job_request(self, job_id: str) -> dict[str, Any]:
        return dict(json.loads(self._get(f"{self._job(job_id)}/request.json", f"no job {job_id!r}")))

    def put_result(self, job_id: str, result_id: str, motion: Motion, report: Report) -> None:
        d = f"{self._job(job_id)}/results/{_safe_id(result_id)}"
        self.objects.put(f"{d}.npz", npz_bytes(motion_to_arrays(motion)))
        self.objects.put(f"{d}.json", report.model_dump_json().encode())

    def delete_result(self, job_id: str, result_id: str) -> None:
        """Remove a result's motion and report (nothing when there is none)."""
        d = f"{self._job(job_id)}/results/{_safe_id(result_id)}"
        self.objects.delete(f"{d}.json")
        self.objects.delete(f"{d}.npz")

    def result_motion(self, job_id: str, result_id: str) -> Motion:
        key = f"{self._job(job_id)}/results/{_safe_id(result_id)}.npz"
        data = self._get(key, f"job {job_id!r} has no result {result_id!r}")
        try:
            return motion_from_arrays(load_npz(data))
        except (ValueError, MotionError) as exc:
            raise NotFoundError(f"result {result_id!r} is unreadable: {exc}") from None

    def result_report(self, job_id: str, result_id: str) -> Report:
        key = f"{self._job(job_id)}/results/{_safe_id(result_id)}.json"
        return Report.model_validate_json(self._get(key, f"job {job_id!r} has no result {result_id!r}"))

    # -- event archives and derived bytes -------------------------------------------------------
    def put_events(self, job_id: str, lines: list[str]) -> None:
        """Replace a job's event archive (one JSON event per line)."""
        self.objects.put(f"{self._job(job_id)}/events.jsonl", ("\n".join(lines) + "\n").encode())

    def append_event(self, job_id: str, line: str) -> None:
        """Add one event line to a job's archive (a file append when local; a read and a whole
        write on an object store, which has no append)."""
        key = f"{self._job(job_id)}/events.jsonl"
        own = self.objects.local_path(key)
        if own is not None:
            own.parent.mkdir(parents=True, exist_ok=True)
            with open(own, "a", encoding="utf-8") as fh:
                fh.write(line + "\n")
            return
        try:
            old = self.objects.get(key)
        except ObjectNotFound:
            old = b""
        self.objects.put(key, old + line.encode() + b"\n")

    def events(self, job_id: str) -> list[str]:
        """The lines of a job's event archive (empty when there is none)."""
        try:
            data = self.objects.get(f"{self._job(job_id)}/events.jsonl")
        except ObjectNotFound:
            return []
        return [line for line in data.decode("utf-8").splitlines() if line.strip()]

    def put_event_batch(self, job_id: str, first_id: int, lines: list[str]) -> None:
        """Store a batch of a running job's events (``lines``, from event ``first_id`` on) beside
        its archive (``jobs/<id>/events/<first id>.jsonl``), until its whole archive is written."""
        if first_id < 1:
            raise ValueError(f"event ids start at 1, not {first_id}")
        key = f"{self._job(job_id)}/events/{first_id:010d}.jsonl"
        self.objects.put(key, ("\n".join(lines) + "\n").encode())

    def event_batches(self, job_id: str) -> list[str]:
        """The lines of a job's event batches (:meth:`put_event_batch`), in id order of their first."""
        prefix = f"{self._job(job_id)}/events"
        lines: list[str] = []
        for name in self.objects.children(prefix):
            try:
                data = self.objects.get(f"{prefix}/{name}")
            except (ObjectNotFound, ValueError):  # removed meanwhile (the whole archive was written)
                continue
            lines.extend(line for line in data.decode("utf-8").splitlines() if line.strip())
        return lines

    def delete_event_batches(self, job_id: str) -> None:
        """Remove a job's event batches (its whole archive holds them)."""
        self.objects.delete_prefix(f"{self._job(job_id)}/events")

    def put_export(self, job_id: str, name: str, data: bytes) -> None:
        """Store derived bytes of a job's result (an export) under ``name`` (a safe file name)."""
        self.objects.put(self._export_key(job_id, name), data)

    def export_bytes(self, job_id: str, name: str) -> bytes:
        """Bytes stored by :meth:`put_export` (:class:`NotFoundError` when there are none)."""
        return self._get(self._export_key(job_id, name), f"job {job_id!r} has no export {name!r}")

    def open_export(self, job_id: str, name: str) -> BinaryIO:
        """A stored export opened for reading in chunks, never read whole (:class:`NotFoundError`
        when not made yet)."""
        try:
            return self.objects.open(self._export_key(job_id, name))
        except ObjectNotFound:
            raise NotFoundError(f"job {job_id!r} has no export {name!r}") from None

    def _export_key(self, job_id: str, name: str) -> str:
        if not name or "/" in name or name.startswith(".") or len(name) > 200:
            raise NotFoundError(f"no such export {name!r}")
        return f"{self._job(job_id)}/exports/{name}"

    def result_shape(self, job_id: str, result_id: str) -> tuple[int, int, float]:
        """``(frames, joints, fps)`` of a stored result from its arrays' headers only (no array is
        read: what an API decides an export's size by)."""
        import zipfile

        key = f"{self._job(job_id)}/results/{_safe_id(result_id)}.npz"
        try:
            fh = self.objects.open(key)
        except ObjectNotFound:
            raise NotFoundError(f"job {job_id!r} has no result {result_id!r}") from None
        try:
            with fh, zipfile.ZipFile(fh if _seekable(fh) else io.BytesIO(fh.read())) as zf:
                with zf.open("rotations.npy") as member:
                    major, _ = np.lib.format.read_magic(member)
                    read_header = (
                        np.lib.format.read_array_header_1_0
                        if major == 1
                        else np.lib.format.read_array_header_2_0
                    )
                    shape, _, _ = read_header(member)
                with zf.open("fps.npy") as member:
                    fps = float(np.lib.format.read_array(member, allow_pickle=False))
        except (KeyError, ValueError, OSError, zipfile.BadZipFile) as exc:
            raise NotFoundError(f"result {result_id!r} is unreadable: {exc}") from None
        return int(shape[0]), int(shape[1]), fps

    # -- staged uploads: bytes kept until a worker has checked them (workers.tasks) -------------
    # Removed by the small job that reads them, by whoever publishes that job's terminal event
    # (workers.records.settle_task: a parse killed by its limits, dead-lettered or cancelled), by
    # the API when no job will read them, and, for whatever a lost process left, by
    # sweep_staged (run by every worker and the embedded backend).
    def stage(self, data: Source) -> str:
        """Keep an upload's bytes (or an open file's, streamed) under a new key until a worker has
        checked them; the key."""
        key = uuid.uuid4().hex
        self.put_staged(key, data)
        return key

    def put_staged(self, key: str, data: Source) -> None:
        """Keep an upload's bytes until a worker has checked them (:meth:`delete_staged` after)."""
        self._write(f"staged/{_safe_id(key)}", data)

    def staged_bytes(self, key: str) -> bytes:
        return self._get(f"staged/{_safe_id(key)}", f"no staged upload {key!r}")

    def delete_staged(self, key: str) -> None:
        self.objects.delete(f"staged/{_safe_id(key)}")

    def staged_keys(self) -> list[str]:
        """The keys of every staged upload."""
        return self.objects.children("staged")

    def sweep_staged(self, older_than_s: float, now_s: float | None = None) -> list[str]:
        """Remove the staged uploads written more than ``older_than_s`` seconds ago (orphans: the
        process that staged or was to read them is gone); their keys."""
        cutoff = (time.time() if now_s is None else now_s) - older_than_s
        removed = []
        for key in self.staged_keys():
            try:
                if self.objects.modified(f"staged/{key}") >= cutoff:
                    continue
                self.delete_staged(key)
            except (ObjectNotFound, NotFoundError, ValueError):  # gone meanwhile, or not a key of ours
                continue
            removed.append(key)
        return removed
