"""Ownership checks of the routes: what a :class:`~service.deps.Principal` may see and change.

Clips, files and databases are content-addressed and shared: each records the principals holding it
and each holder's own record (:meth:`workers.store.Store.holders`: the name it used, when, the build
it queued), so a principal sees its own name and time over the shared bytes, never another's. Jobs
have one owner (``JobInfo.owner``). A principal sees only what it holds (an admin, or the single user
of a server without tokens, sees everything); anything else answers 404 exactly like a thing that
does not exist, so ids do not leak.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from fastapi import Response, status

from schemas import ClipInfo, DatabaseInfo, JobInfo
from schemas.files import FileInfo
from workers.store import NotFoundError, Owned, Store, Visible, now

from .deps import Principal


def visible(store: Store, principal: Principal, *kinds: Owned) -> Visible:
    """``visible(id)`` for the given kinds of things (any kind holding the id counts)."""
    if principal.admin:
        return lambda _id: True
    return lambda item_id: any(principal.name in store.owners(kind, item_id) for kind in kinds)


Info = TypeVar("Info", ClipInfo, FileInfo, DatabaseInfo)


def seen(store: Store, principal: Principal, kind: Owned, info: Info) -> Info:
    """``info`` as the principal sees it: the shared facts with its own record (name, upload time,
    build job) over them; the shared info itself when it has no record (holds recorded before
    records were, or an admin looking at another's)."""
    return _with_record(info, store.holders(kind, info.id).get(principal.name))


def _with_record(info: Info, record: dict[str, Any] | None) -> Info:
    if not record:
        return info
    fields = type(info).model_fields
    return type(info).model_validate(info.model_dump() | {k: v for k, v in record.items() if k in fields})


def only_visible(store: Store, principal: Principal, kind: Owned, items: Sequence[Info]) -> list[Info]:
    """The ``items`` of ``kind`` the principal holds, as it sees them, oldest (its time) first."""
    out: list[Info] = []
    for item in items:
        held = store.holders(kind, item.id)
        if principal.admin or principal.name in held:
            out.append(_with_record(item, held.get(principal.name)))
    return sorted(out, key=lambda i: i.created_at)


def record(name: str | None, **more: Any) -> dict[str, Any]:
    """A new holder's own record (JSON values): the name it used, now, and ``more`` (a database's
    ``build_job``: the build it queued, None when it found the database built or building)."""
    return {"name": name, "created_at": now().isoformat(), **more}


def hold(
    store: Store,
    principal: Principal,
    kind: Owned,
    item_id: str,
    response: Response,
    name: str | None = None,
    restore: Callable[[], None] | None = None,
    more: dict[str, Any] | None = None,
) -> None:
    """Record the principal as a holder of a content-addressed upload under its own ``name`` (and
    ``more`` of its own facts, e.g. a clip's ``units``; an earlier record is kept) (``restore``
    writes the bytes back when another holder deleted them meanwhile); the answer is 200 instead
    of 201 when it held the same bytes already."""
    if not store.add_owner(kind, item_id, principal.name, record(name, **(more or {})), restore):
        response.status_code = status.HTTP_200_OK


def release(
    store: Store, principal: Principal, kind: Owned, item_id: str, delete: Callable[[str], None]
) -> Response:
    """Drop the principal's hold; the thing is deleted when no other principal holds it (an admin
    deletes it outright), atomically against another principal's upload of the same bytes
    (:mod:`workers.holders`). Answers 204. The last holder's delete writes nothing first on a
    local store, so it works on a full disk (space is freed through the API)."""
    store.release(kind, item_id, principal.name, delete, force=principal.admin)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


def find_clip(store: Store, principal: Principal, ref: str, also: frozenset[str] = frozenset()) -> ClipInfo:
    """A clip by id, or by the name the principal uploaded it with (its newest such upload), among
    its clips and the ids ``also`` (404 otherwise); as the principal sees it."""
    mine = visible(store, principal, "clips")
    try:
        info = store.clip_info(ref)
        if info.id in also or mine(info.id):
            return seen(store, principal, "clips", info)
    except NotFoundError:
        pass
    held = (seen(store, principal, "clips", c) for c in store.list_clips() if c.id in also or mine(c.id))
    matches = [c for c in held if c.name == ref or c.name.removesuffix(".gz") == ref]
    if not matches:
        raise NotFoundError(f"no uploaded clip named {ref!r}; upload it first (POST /v1/clips)")
    return max(matches, key=lambda c: c.created_at)


def clip_for(store: Store, principal: Principal, ref: str) -> ClipInfo:
    """A clip the principal holds, by id or upload name (404 otherwise), as it sees it."""
    return find_clip(store, principal, ref)


def file_for(store: Store, principal: Principal, file_id: str) -> FileInfo:
    """A file the principal holds (404 otherwise), as it sees it."""
    info = store.file_info(file_id)
    if not principal.may(store.owners("files", info.id)):
        raise NotFoundError(f"no file {file_id!r}")
    return seen(store, principal, "files", info)


def database_for(store: Store, principal: Principal, db_id: str) -> DatabaseInfo:
    """A database the principal holds (404 otherwise), as it sees it."""
    info = store.database_info(db_id)
    if not principal.may(store.owners("databases", info.id)):
        raise NotFoundError(f"no database {db_id!r}")
    return seen(store, principal, "databases", info)


def job_for(principal: Principal, info: JobInfo) -> JobInfo:
    """``info`` when the principal owns the job (404 otherwise)."""
    if not principal.may(info.owner):
        raise NotFoundError(f"no job {info.id!r}")
    return info
