"""A process's local cache of databases downloaded from an object store, bounded by bytes.

An engine memory-maps a database's ``.npy`` files (:mod:`engines.container`), which needs them on
a local disk. With an object store (``s3://``), :class:`DiskCache` downloads a database's arrays
once into ``<data dir>/cache/databases/<id>/`` and every engine process on the host maps the same
files (one copy in the page cache). The cache is a cache only: anything in it can be deleted at any
time and is downloaded again.

* A download goes to a temporary directory renamed into place when complete (the manifest written
  last), so two processes fetching the same database never see half of one; the loser of the rename
  discards its copy.
* After each download the least recently used databases (by the manifest's modification time,
  stamped on every use) are deleted until the cache holds at most ``max_bytes``; the one just
  fetched stays even when it alone is larger. Deleting files another process has mapped is safe on
  POSIX: its pages stay valid until it unmaps them.
* A use is stamped with the nanosecond clock (``time.time_ns``), never later than the process's
  previous stamp: the kernel's own file times tick in jiffies (1-10 ms), so two uses in quick
  succession would otherwise tie and the order of use be lost.
* A full disk (``ENOSPC``, a quota, the file-size limit) is the cache's problem, not the user's: the
  least recently used database is evicted and the download tried again, until it fits or nothing
  is left to evict; then :class:`CacheFull` says so (the worker gives the job back to the queue for
  another host, :mod:`workers.redis_worker`, and tells the operator).
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

from engines.base import container

from .storage_errors import FULL

log = logging.getLogger("segue.cache")


class CacheFull(Exception):
    """A database does not fit in this process's cache even with every other one evicted (the
    disk holding ``SEGUE_DATA_DIR`` is full): a problem of this host, for its operator."""

    def __init__(self, db_id: str, root: Path, needed: int, cause: OSError) -> None:
        super().__init__(
            f"the cache disk at {root} is full ({cause.strerror or cause}) and nothing more can be "
            f"evicted: database {db_id} ({needed / 2**20:.1f} MiB) does not fit; free space on that "
            "disk or lower SEGUE_DISK_CACHE_MB"
        )
        self.db_id, self.root, self.needed = db_id, root, needed


class ObjectCache(Protocol):
    """A shared cache of store objects in front of the object store (the Redis database cache)."""

    def get(self, key: str) -> bytes | None:
        """The cached bytes, or None."""
        ...

    def put(self, key: str, data: bytes) -> None:
        """Cache ``data`` (failures are the cache's to log, never the caller's)."""
        ...

    def wants(self, size: int) -> bool:
        """Whether an object of ``size`` bytes belongs in the cache."""
        ...


Fetch = Callable[[str, Path], None]
"""``fetch(file, path)``: write the database object ``arrays/<file>`` (or ``arrays.json``) to ``path``."""


class DiskCache:
    """Databases downloaded under ``root`` (one directory each), at most ``max_bytes`` in all."""

    def __init__(self, root: str | Path, max_bytes: int) -> None:
        self.root = Path(root)
        self.max_bytes = max_bytes
        self._lock = threading.Lock()
        self._last_use_ns = 0

    def _stamp(self, manifest: Path) -> None:
        """Record a use of the database whose manifest is ``manifest`` (``OSError`` when it is gone)."""
        with self._lock:
            now = max(time.time_ns(), self._last_use_ns + 1)
            self._last_use_ns = now
        os.utime(manifest, ns=(now, now))

    def _dir(self, db_id: str) -> Path:
        return self.root / db_id

    def path_if_cached(self, db_id: str) -> Path | None:
        """The cached copy's directory (its use recorded), or None."""
        d = self._dir(db_id)
        manifest = d / container.MANIFEST
        try:
            self._stamp(manifest)
        except OSError:
            return None
        return d

    def fetch(self, db_id: str, manifest: container.Manifest, fetch: Fetch) -> Path:
        """The directory of the database's arrays, downloaded with ``fetch`` unless cached. On a
        full disk the least recently used databases are evicted one by one and the download tried
        again; :class:`CacheFull` once nothing is left to evict."""
        while True:
            cached = self.path_if_cached(db_id)
            if cached is not None:
                return cached
            try:
                return self._download(db_id, manifest, fetch)
            except OSError as exc:
                if exc.errno not in FULL:
                    raise
                evicted = self._evict_oldest(keep=db_id)
                if evicted is None:
                    raise CacheFull(db_id, self.root, manifest.total_bytes, exc) from exc
                log.warning(
                    "cache disk %s full (%s): evicted database %s to make room for %s",
                    self.root,
                    exc.strerror or exc,
                    evicted,
                    db_id,
                )

    def _evict_oldest(self, keep: str) -> str | None:
        """Evict the least recently used database but ``keep``; its id (None: nothing to evict)."""
        with self._lock:
            for _, _, db_id in self.entries():
                if db_id != keep:
                    self.evict(db_id)
                    return db_id
        return None

    def _download(self, db_id: str, manifest: container.Manifest, fetch: Fetch) -> Path:
        self.root.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=self.root, prefix=f".{db_id}."))
        try:
            (tmp / container.ARRAYS_DIR).mkdir()
            for name, file in manifest.files.items():
                path = tmp / container.ARRAYS_DIR / file
                fetch(f"{container.ARRAYS_DIR}/{file}", path)
                size = path.stat().st_size
                if size != manifest.sizes[name]:
                    raise OSError(f"database {db_id}: {file} has {size} bytes, not {manifest.sizes[name]}")
            (tmp / container.MANIFEST).write_bytes(manifest.to_bytes())
            try:
                tmp.rename(self._dir(db_id))
            except OSError:  # another process got there first: use its copy
                shutil.rmtree(tmp, ignore_errors=True)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        with contextlib.suppress(OSError):  # evicted at once by another process: fetched again next time
            self._stamp(self._dir(db_id) / container.MANIFEST)
        self.evict_over(keep=db_id)
        return self._dir(db_id)

    def entries(self) -> list[tuple[int, int, str]]:
        """``(last use ns, bytes, id)`` of every complete cached database, oldest first."""
        out: list[tuple[int, int, str]] = []
        if not self.root.is_dir():
            return out
        for d in self.root.iterdir():
            manifest = d / container.MANIFEST
            if d.name.startswith(".") or not manifest.is_file():
                continue
            try:
                size = container.read_manifest(d).total_bytes
                out.append((manifest.stat().st_mtime_ns, size, d.name))
            except (OSError, container.ContainerError):
                continue
        return sorted(out)

    def total_bytes(self) -> int:
        return sum(size for _, size, _ in self.entries())

    def evict_over(self, keep: str | None = None) -> list[str]:
        """Delete the least recently used databases until at most ``max_bytes`` stay; their ids."""
        with self._lock:
            entries = self.entries()
            total = sum(size for _, size, _ in entries)
            evicted = []
            for _, size, db_id in entries:
                if total <= self.max_bytes:
                    break
                if db_id == keep:
                    continue
                self.evict(db_id)
                total -= size
                evicted.append(db_id)
            return evicted

    def evict(self, db_id: str) -> None:
        """Drop one database's copy (renamed away first, so no reader sees a half-deleted one)."""
        d = self._dir(db_id)
        if not d.exists():
            return
        gone = self.root / f".{db_id}.evicted.{os.getpid()}.{threading.get_ident()}"
        with contextlib.suppress(OSError):
            d.rename(gone)
            shutil.rmtree(gone, ignore_errors=True)
