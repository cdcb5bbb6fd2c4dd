"""Characters for result downloads: ``?character=`` names an uploaded BVH clip (by id or upload
name) or an uploaded glTF/GLB file (by id) whose skeleton the result is retargeted onto
(:func:`motion.retarget.retarget`, in a worker: :mod:`workers.result_export`). Here the name is
only resolved to an upload the principal holds (metadata, no bytes read)."""

from __future__ import annotations

from workers.result_export import CharacterRef, RestPose, RootMotion
from workers.store import NotFoundError, Store

from .deps import Principal
from .owners import clip_for, file_for

__all__ = ["CharacterRef", "RestPose", "RootMotion", "character_ref"]


def character_ref(store: Store, principal: Principal, ref: str) -> CharacterRef:
    """The upload ``ref`` names (a clip the principal holds, else a file it holds). Raises
    ``NotFoundError`` (404) when it names neither."""
    try:
        info = clip_for(store, principal, ref)
    except NotFoundError:
        try:
            finfo = file_for(store, principal, ref)
        except NotFoundError:
            raise NotFoundError(
                f"no character {ref!r}: upload a BVH to /v1/clips or a GLB/glTF to /v1/files first"
            ) from None
        return CharacterRef("file", finfo.id, finfo.name, ref)
    return CharacterRef("clip", info.id, info.name, ref, info.units)
