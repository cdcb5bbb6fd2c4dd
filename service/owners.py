"""Ownership checks of the routes: what a :class:`~service.deps.Principal` may see and change.

Clips, files and databases are content-addressed and shared: each records the principals holding it
(:meth:`workers.store.Store.owners`); jobs have one owner (``JobInfo.owner``). A principal sees only
what it holds (an admin, or the single user of a server without tokens, sees everything); anything
else answers 404 exactly like a thing that does not exist, so ids do not leak.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol, TypeVar

from fastapi import Response, status

from schemas import ClipInfo, DatabaseInfo, JobInfo
from schemas.files import FileInfo
from workers.store import NotFoundError, Owned, Store, Visible

from .deps import Principal


def visible(store: Store, principal: Principal, *kinds: Owned) -> Visible:
    """``visible(id)`` for the given kinds of things (any kind holding the id counts)."""
    if principal.admin:
        return lambda _id: True
    return lambda item_id: any(principal.name in store.owners(kind, item_id) for kind in kinds)


class HasId(Protocol):
    @property
    def id(self) -> str: ...


Item = TypeVar("Item", bound=HasId)


def only_visible(store: Store, principal: Principal, kind: Owned, items: Sequence[Item]) -> list[Item]:
    """The ``items`` of ``kind`` the principal holds, in their order."""
    mine = visible(store, principal, kind)
    return [item for item in items if mine(item.id)]


def hold(store: Store, principal: Principal, kind: Owned, item_id: str, response: Response) -> None:
    """Record the principal as a holder of a content-addressed upload; the answer is 200 instead
    of 201 when it held the same bytes already."""
    if not store.add_owner(kind, item_id, principal.name):
        response.status_code = status.HTTP_200_OK


def release(
    store: Store, principal: Principal, kind: Owned, item_id: str, delete: Callable[[str], None]
) -> Response:
    """Drop the principal's hold; the thing is deleted when no other principal holds it (an admin
    deletes it outright). Answers 204. The last holder's delete writes nothing first, so it works
    on a full disk (space is freed through the API)."""
    if principal.admin or store.owners(kind, item_id) <= {principal.name}:
        delete(item_id)
    else:
        store.remove_owner(kind, item_id, principal.name)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


def clip_for(store: Store, principal: Principal, ref: str) -> ClipInfo:
    """A clip the principal holds, by id or upload name (404 otherwise)."""
    return store.find_clip(ref, visible(store, principal, "clips"))


def file_for(store: Store, principal: Principal, file_id: str) -> FileInfo:
    """A file the principal holds (404 otherwise)."""
    info = store.file_info(file_id)
    if not principal.may(store.owners("files", info.id)):
        raise NotFoundError(f"no file {file_id!r}")
    return info


def database_for(store: Store, principal: Principal, db_id: str) -> DatabaseInfo:
    """A database the principal holds (404 otherwise)."""
    info = store.database_info(db_id)
    if not principal.may(store.owners("databases", info.id)):
        raise NotFoundError(f"no database {db_id!r}")
    return info


def job_for(principal: Principal, info: JobInfo) -> JobInfo:
    """``info`` when the principal owns the job (404 otherwise)."""
    if not principal.may(info.owner):
        raise NotFoundError(f"no job {info.id!r}")
    return info
