"""The durable store: clips, databases, jobs and results on disk (one directory tree).

Layout under ``root``::

    clips/<sha256>.bvh            uploaded bytes (as uploaded, possibly gzip)
    clips/<sha256>.json           ClipInfo
    clips/<sha256>.owners         JSON list of the principals holding the clip (likewise files/,
                                  databases/<id>/owners): content-addressed things are shared, each
                                  holder sees and deletes only its own hold
    databases/<id>/spec.json      the validated spec (clip references resolved to ids)
    databases/<id>/info.json      DatabaseInfo
    databases/<id>/data.npz       motion library + kind-specific arrays (allow_pickle=False)
    jobs/<id>/request.json        {"kind", "payload"}
    jobs/<id>/info.json           JobInfo
    jobs/<id>/results/<rid>.npz   result motion (motion.serialize arrays)
    jobs/<id>/results/<rid>.json  Report

Every write goes to a temporary file first and is renamed into place, so a crash or a concurrent
reader never sees half a file, and nothing already stored is changed by a failed request.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import tempfile
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import numpy as np

from motion import Motion, MotionError
from motion.bvh import BvhLimits, detect_units, parse_bvh
from motion.serialize import motion_from_arrays, motion_to_arrays
from schemas import ClipInfo, DatabaseInfo, JobInfo, Report
from schemas.files import FileInfo

Arrays = dict[str, Any]
Owned = Literal["clips", "files", "databases"]
Visible = Callable[[str], bool]
"""``visible(id)``: may the caller see the clip, file or database with this id (ownership filter)."""


class NotFoundError(LookupError):
    """A clip, database, job or result that does not exist."""


def now() -> datetime:
    return datetime.now(UTC)


def _atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def npz_bytes(arrays: Arrays) -> bytes:
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


def _safe_id(value: str) -> str:
    if not value or any(c not in "0123456789abcdefghijklmnopqrstuvwxyz-_" for c in value) or len(value) > 80:
        raise NotFoundError(f"no such id {value!r}")
    return value


class Store:
    """Clips, databases, jobs and results under one directory (see the module docstring)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        for sub in ("clips", "files", "databases", "jobs"):
            (self.root / sub).mkdir(parents=True, exist_ok=True)

    # -- clips --------------------------------------------------------------------------------
    def put_clip(
        self, name: str, data: bytes, limits: BvhLimits | None = None, units: str | None = None
    ) -> ClipInfo:
        """Validate and store an uploaded clip; the same bytes are stored once (content address).

        Raises :class:`motion.MotionError` (a ``BvhError``) for invalid content; nothing is written then.
        """
        digest = hashlib.sha256(data).hexdigest()
        existing = self.root / "clips" / f"{digest}.json"
        if existing.exists():
            return ClipInfo.model_validate_json(existing.read_bytes())
        motion = parse_bvh(data, units=units, limits=limits, source=name, name=name)
        guess = detect_units(motion)
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
        )
        _atomic_write(self.root / "clips" / f"{digest}.bvh", data)
        _atomic_write(existing, info.model_dump_json().encode())
        return info

    def clip_info(self, clip_id: str) -> ClipInfo:
        p = self.root / "clips" / f"{_safe_id(clip_id)}.json"
        if not p.exists():
            raise NotFoundError(f"no clip {clip_id!r}")
        return ClipInfo.model_validate_json(p.read_bytes())

    def clip_bytes(self, clip_id: str) -> bytes:
        p = self.root / "clips" / f"{_safe_id(clip_id)}.bvh"
        if not p.exists():
            raise NotFoundError(f"no clip {clip_id!r}")
        return p.read_bytes()

    def list_clips(self) -> list[ClipInfo]:
        infos = [ClipInfo.model_validate_json(p.read_bytes()) for p in (self.root / "clips").glob("*.json")]
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
        for suffix in (".json", ".bvh", ".owners"):
            (self.root / "clips" / f"{info.id}{suffix}").unlink(missing_ok=True)

    # -- holders of content-addressed things ----------------------------------------------------
    def _owners_path(self, kind: Owned, item_id: str) -> Path:
        if kind == "databases":
            return self.db_dir(item_id) / "owners"
        return self.root / kind / f"{_safe_id(item_id)}.owners"

    def owners(self, kind: Owned, item_id: str) -> set[str]:
        """The principals holding a clip, file or database (empty: recorded before owners were)."""
        p = self._owners_path(kind, item_id)
        try:
            return set(json.loads(p.read_bytes()))
        except (OSError, ValueError):
            return set()

    def add_owner(self, kind: Owned, item_id: str, principal: str) -> bool:
        """Record ``principal`` as a holder; False when it held it already."""
        held = self.owners(kind, item_id)
        if principal in held:
            return False
        _atomic_write(self._owners_path(kind, item_id), json.dumps(sorted(held | {principal})).encode())
        return True

    def remove_owner(self, kind: Owned, item_id: str, principal: str) -> set[str]:
        """Drop ``principal``'s hold; returns the holders left."""
        held = self.owners(kind, item_id) - {principal}
        _atomic_write(self._owners_path(kind, item_id), json.dumps(sorted(held)).encode())
        return held

    # -- databases ----------------------------------------------------------------------------
    def db_dir(self, db_id: str) -> Path:
        return self.root / "databases" / _safe_id(db_id)

    def put_database_info(self, info: DatabaseInfo, spec: dict[str, Any] | None = None) -> None:
        d = self.db_dir(info.id)
        if spec is not None:
            _atomic_write(d / "spec.json", json.dumps(spec, sort_keys=True).encode())
        _atomic_write(d / "info.json", info.model_dump_json().encode())

    def database_info(self, db_id: str) -> DatabaseInfo:
        p = self.db_dir(db_id) / "info.json"
        if not p.exists():
            raise NotFoundError(f"no database {db_id!r}")
        return DatabaseInfo.model_validate_json(p.read_bytes())

    def database_spec(self, db_id: str) -> dict[str, Any]:
        p = self.db_dir(db_id) / "spec.json"
        if not p.exists():
            raise NotFoundError(f"no database {db_id!r}")
        return dict(json.loads(p.read_bytes()))

    def list_databases(self) -> list[DatabaseInfo]:
        out = []
        for d in (self.root / "databases").iterdir():
            if (d / "info.json").exists():
                out.append(DatabaseInfo.model_validate_json((d / "info.json").read_bytes()))
        return sorted(out, key=lambda i: i.created_at)

    def put_database_arrays(self, db_id: str, data: bytes) -> None:
        _atomic_write(self.db_dir(db_id) / "data.npz", data)

    def database_arrays_bytes(self, db_id: str) -> bytes:
        p = self.db_dir(db_id) / "data.npz"
        if not p.exists():
            raise NotFoundError(f"database {db_id!r} has no built data")
        return p.read_bytes()

    def delete_database(self, db_id: str) -> None:
        d = self.db_dir(db_id)
        if not d.exists():
            raise NotFoundError(f"no database {db_id!r}")
        shutil.rmtree(d, ignore_errors=True)

    # -- other input files (MIDI...) ------------------------------------------------------------
    def put_file(self, name: str, data: bytes) -> FileInfo:
        """Store an uploaded input file once per content hash (no parsing: engines validate it)."""
        digest = hashlib.sha256(data).hexdigest()
        meta = self.root / "files" / f"{digest}.json"
        if meta.exists():
            return FileInfo.model_validate_json(meta.read_bytes())
        info = FileInfo(
            id=digest, name=name, size_bytes=len(data), media_type=_media_type(data), created_at=now()
        )
        _atomic_write(self.root / "files" / f"{digest}.bin", data)
        _atomic_write(meta, info.model_dump_json().encode())
        return info

    def delete_file(self, file_id: str) -> None:
        info = self.file_info(file_id)
        for suffix in (".json", ".bin", ".owners"):
            (self.root / "files" / f"{info.id}{suffix}").unlink(missing_ok=True)

    def file_info(self, file_id: str) -> FileInfo:
        p = self.root / "files" / f"{_safe_id(file_id)}.json"
        if not p.exists():
            raise NotFoundError(f"no file {file_id!r}")
        return FileInfo.model_validate_json(p.read_bytes())

    def file_bytes(self, file_id: str) -> bytes:
        p = self.root / "files" / f"{_safe_id(file_id)}.bin"
        if not p.exists():
            raise NotFoundError(f"no file {file_id!r}")
        return p.read_bytes()

    def list_files(self) -> list[FileInfo]:
        infos = [FileInfo.model_validate_json(p.read_bytes()) for p in (self.root / "files").glob("*.json")]
        return sorted(infos, key=lambda f: f.created_at)

    def input_bytes(self, upload_id: str) -> bytes:
        """The bytes of an uploaded clip or file by id."""
        try:
            return self.clip_bytes(upload_id)
        except NotFoundError:
            return self.file_bytes(upload_id)

    def find_input(self, ref: str, visible: Visible | None = None) -> str:
        """Resolve a request's input reference to an upload id: a clip or file id, or the name of an
        uploaded clip or file (the newest upload of that name), among those ``visible`` accepts."""
        ok = visible or (lambda _id: True)
        for lookup in (self.clip_info, self.file_info):
            try:
                found = lookup(ref).id
            except NotFoundError:
                continue
            if ok(found):
                return found
        base = ref.replace("\\", "/").rsplit("/", 1)[-1]
        named: list[tuple[datetime, str]] = [
            (c.created_at, c.id)
            for c in self.list_clips()
            if (c.name in (ref, base) or c.name.removesuffix(".gz") in (ref, base)) and ok(c.id)
        ]
        named += [(f.created_at, f.id) for f in self.list_files() if f.name in (ref, base) and ok(f.id)]
        if not named:
            raise NotFoundError(
                f"no uploaded clip or file named {ref!r}; upload it first (POST /v1/clips for BVH, "
                "POST /v1/files for other files)"
            )
        return max(named)[1]

    # -- jobs and results -----------------------------------------------------------------------
    def job_dir(self, job_id: str) -> Path:
        return self.root / "jobs" / _safe_id(job_id)

    def put_job(self, info: JobInfo, request: dict[str, Any] | None = None) -> None:
        d = self.job_dir(info.id)
        if request is not None:
            _atomic_write(d / "request.json", json.dumps(request).encode())
        _atomic_write(d / "info.json", info.model_dump_json().encode())

    def job_info(self, job_id: str) -> JobInfo:
        p = self.job_dir(job_id) / "info.json"
        if not p.exists():
            raise NotFoundError(f"no job {job_id!r}")
        return JobInfo.model_validate_json(p.read_bytes())

    def list_jobs(self) -> list[JobInfo]:
        """Every job, oldest first."""
        out = []
        for d in (self.root / "jobs").iterdir():
            p = d / "info.json"
            if p.exists():
                out.append(JobInfo.model_validate_json(p.read_bytes()))
        return sorted(out, key=lambda i: i.created_at)

    def delete_job(self, job_id: str) -> None:
        """Remove a job's record, request, events and results (NotFoundError when there is none)."""
        d = self.job_dir(job_id)
        if not (d / "info.json").exists():
            raise NotFoundError(f"no job {job_id!r}")
        shutil.rmtree(d, ignore_errors=True)

    def job_request(self, job_id: str) -> dict[str, Any]:
        p = self.job_dir(job_id) / "request.json"
        if not p.exists():
            raise NotFoundError(f"no job {job_id!r}")
        return dict(json.loads(p.read_bytes()))

    def put_result(self, job_id: str, result_id: str, motion: Motion, report: Report) -> None:
        d = self.job_dir(job_id) / "results"
        _atomic_write(d / f"{_safe_id(result_id)}.npz", npz_bytes(motion_to_arrays(motion)))
        _atomic_write(d / f"{result_id}.json", report.model_dump_json().encode())

    def result_motion(self, job_id: str, result_id: str) -> Motion:
        p = self.job_dir(job_id) / "results" / f"{_safe_id(result_id)}.npz"
        if not p.exists():
            raise NotFoundError(f"job {job_id!r} has no result {result_id!r}")
        try:
            return motion_from_arrays(load_npz(p.read_bytes()))
        except (ValueError, MotionError) as exc:
            raise NotFoundError(f"result {result_id!r} is unreadable: {exc}") from None

    def result_report(self, job_id: str, result_id: str) -> Report:
        p = self.job_dir(job_id) / "results" / f"{_safe_id(result_id)}.json"
        if not p.exists():
            raise NotFoundError(f"job {job_id!r} has no result {result_id!r}")
        return Report.model_validate_json(p.read_bytes())
