"""Characters for result downloads: ``?character=`` names an uploaded BVH clip (by id or upload
name) or an uploaded glTF/GLB file (by id) whose skeleton the result is retargeted onto
(:func:`motion.retarget.retarget`)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from motion import Motion
from motion.bvh import BvhLimits, parse_bvh
from motion.retarget.character import gltf_character
from motion.retarget.transfer import zero_pose
from workers.store import NotFoundError, Store

from .deps import Principal
from .owners import clip_for, file_for


class RestPose(StrEnum):
    """A BVH character's rest pose: its first frame or the zero-rotation pose of its offsets."""

    first = "first"
    zero = "zero"


class RootMotion(StrEnum):
    """Where a retargeted result's root motion goes (:mod:`motion.retarget.rootmotion`)."""

    root = "root"
    hips = "hips"
    none = "none"


@dataclass(frozen=True, slots=True)
class Character:
    """A character: its rest pose (a one-frame motion) and, for an uploaded glTF/GLB file, the
    file itself (a GLB download is that file with the animation added)."""

    motion: Motion
    gltf: bytes | None = None


def load_character(
    store: Store, principal: Principal, ref: str, rest: RestPose, limits: BvhLimits
) -> Character:
    """The character ``ref`` (a clip the principal holds, else a file it holds) in its rest pose.
    Raises ``NotFoundError`` (404) when it names neither, and :class:`motion.MotionError` (422)
    for a file that is not a glTF skin."""
    try:
        info = clip_for(store, principal, ref)
    except NotFoundError:
        try:
            finfo = file_for(store, principal, ref)
        except NotFoundError:
            raise NotFoundError(
                f"no character {ref!r}: upload a BVH to /v1/clips or a GLB/glTF to /v1/files first"
            ) from None
        raw = store.file_bytes(finfo.id)
        return Character(gltf_character(raw, name=finfo.name), raw)
    motion = parse_bvh(
        store.clip_bytes(info.id), units=info.units, limits=limits, source=info.name, name=info.name
    )
    return Character(zero_pose(motion) if rest == RestPose.zero else motion.slice(0, 1))
