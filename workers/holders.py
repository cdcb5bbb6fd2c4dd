"""Who holds a content-addressed clip, file or database, and under which name: one small object per
thing (``clips/<sha256>.owners``, ``files/<sha256>.owners``, ``databases/<id>/owners``).

Its format (JSON)::

    {"v": 7, "holders": {"alice": {"name": "walk.bvh", "created_at": "...", "build_job": null}}}

``v`` counts writes, so a compare-and-swap never mistakes a changed-and-changed-back object for
an unchanged one (S3 ETags are content hashes). A holder's record keeps what is its own: the name
it uploaded or built under, when, and the build it queued; the shared info (``ClipInfo`` ...)
keeps the first upload's. Older stores wrote a plain JSON list of names: it still reads, as
holders without records (they see the shared info), and is rewritten in this format on the next
change. ``{"deleting": true}`` marks a delete in progress on an object store (below).

Every change is atomic against every other, in any process:

* **local directory**: an exclusive ``flock`` on the kind's directory (``clips/``, ``files/``,
  ``databases/``) around read-change-write, and around the last holder's delete of the bytes.
  A lock writes nothing, so a delete works on a full disk (the space is freed through the API);
  an O_EXCL lock file or a versioned compare-and-swap would need a write first.
* **S3**: a compare-and-swap on the owners object (``If-Match`` on its ETag, ``If-None-Match: *``
  to create it), retried on 412. The last holder's delete first swaps in ``{"deleting": true}``,
  deletes the bytes, then the owners object; a concurrent upload of the same bytes waits for the
  marker to go (taking it over after :data:`STALE_S` if its deleter died), records its hold, and
  then restores the bytes it has in hand. So bytes a principal holds are never deleted under it.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import time
from collections.abc import Callable, Iterator, Mapping
from typing import Any, cast

from .objects import LocalObjects, ObjectNotFound, Objects, S3Objects
from .timed_objects import untimed

Record = dict[str, Any]
"""A holder's own facts (``name``, ``created_at``, ``build_job``; JSON values); empty: none kept."""

STALE_S = 30.0
"""Seconds after which a ``deleting`` marker whose deleter died is taken over by an upload."""
POLL_S = 0.02


class Holders:
    """The holders of one content-addressed thing: principal -> record (see the module docstring)."""

    def __init__(self, holders: Mapping[str, Record] | None = None, version: int = 0, deleting: bool = False):
        self.holders: dict[str, Record] = dict(holders or {})
        self.version = version
        self.deleting = deleting

    @classmethod
    def parse(cls, data: bytes) -> Holders:
        try:
            value = json.loads(data)
        except ValueError:
            return cls()
        if isinstance(value, list):  # before per-principal records
            return cls({str(name): {} for name in value})
        if not isinstance(value, dict):
            return cls()
        raw = value.get("holders") or {}
        holders = {str(k): dict(v) if isinstance(v, dict) else {} for k, v in raw.items()}
        return cls(holders, int(value.get("v", 0)), bool(value.get("deleting", False)))

    def to_bytes(self) -> bytes:
        body: dict[str, Any] = {"v": self.version + 1, "holders": self.holders}
        if self.deleting:
            body["deleting"] = True
        return json.dumps(body, sort_keys=True).encode()


@contextlib.contextmanager
def _dir_lock(objects: LocalObjects, directory: str) -> Iterator[None]:
    path = objects.root / directory
    path.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


def read(objects: Objects, key: str) -> Holders:
    """The holders recorded under ``key`` (none when there is no owners object)."""
    try:
        return Holders.parse(objects.get(key))
    except ObjectNotFound:
        return Holders()


def hold(
    objects: Objects,
    key: str,
    principal: str,
    record: Record,
    present: Callable[[], bool],
    restore: Callable[[], None] | None,
    replace: bool = False,
) -> bool:
    """Record ``principal`` as a holder with ``record`` (kept as it is when it holds already, unless
    it had none, or ``replace``); then, when the bytes are gone (``present()`` false: deleted by
    another holder meanwhile), ``restore()`` them. True when the principal did not hold the thing before."""
    base = untimed(objects)
    if isinstance(base, S3Objects):
        added = _hold_s3(cast(S3Objects, objects), key, principal, record, replace)
        if restore is not None and not present():
            restore()
        return added
    assert isinstance(base, LocalObjects)
    with _dir_lock(base, key.split("/", 1)[0]):
        current = read(objects, key)
        had = current.holders.get(principal)
        if had is None or replace or (not had and record):
            current.holders[principal] = dict(record)
            objects.put(key, current.to_bytes())
        if restore is not None and not present():
            restore()
        return had is None


def _hold_s3(objects: S3Objects, key: str, principal: str, record: Record, replace: bool) -> bool:
    marker_since: float | None = None
    while True:
        try:
            data, etag = objects.get_tagged(key)
        except ObjectNotFound:
            data, etag = None, None
        current = Holders.parse(data) if data is not None else Holders()
        if current.deleting:
            marker_since = marker_since or time.monotonic()
            if time.monotonic() - marker_since < STALE_S:
                time.sleep(POLL_S)
                continue
            current = Holders(version=current.version)  # its deleter died: take it over
        had = current.holders.get(principal)
        if had is not None and not replace and (had or not record):
            return False
        current.holders[principal] = dict(record)
        if objects.put(key, current.to_bytes(), if_absent=etag is None, if_match=etag):
            return had is None


def release(
    objects: Objects, key: str, principal: str, delete: Callable[[], None], force: bool = False
) -> bool:
    """Drop ``principal``'s hold; when no other principal holds the thing (or ``force``: an admin),
    ``delete()`` it (which must remove the owners object, last). True when it was deleted. Locally
    nothing is written before the delete (it works on a full disk)."""
    base = untimed(objects)
    if isinstance(base, S3Objects):
        return _release_s3(cast(S3Objects, objects), key, principal, delete, force)
    assert isinstance(base, LocalObjects)
    with _dir_lock(base, key.split("/", 1)[0]):
        current = read(objects, key)
        if force or set(current.holders) <= {principal}:
            delete()
            return True
        current.holders.pop(principal, None)
        objects.put(key, current.to_bytes())
        return False


def _release_s3(
    objects: S3Objects, key: str, principal: str, delete: Callable[[], None], force: bool
) -> bool:
    while True:
        try:
            data, etag = objects.get_tagged(key)
        except ObjectNotFound:
            data, etag = None, None
        current = Holders.parse(data) if data is not None else Holders()
        last = force or current.deleting or set(current.holders) <= {principal}
        if last:
            current = Holders(version=current.version, deleting=True)
        else:
            current.holders.pop(principal, None)
        if objects.put(key, current.to_bytes(), if_absent=etag is None, if_match=etag):
            break
    if last:
        delete()  # removes the marker last: a waiting upload then records its hold and restores
    return last
