"""Characters: for result downloads and for the viewer.

``?character=`` on a result download names an uploaded BVH clip (by id or upload name) or an
uploaded glTF/GLB file (by id) whose skeleton the result is retargeted onto
(:func:`motion.retarget.retarget`, in a worker: :mod:`workers.result_export`); here the name is
only resolved to an upload the principal holds (metadata, no bytes read).

The viewer also plays motion that never was a result (a clip, a live session's frames) on a
character: :func:`character_binding` answers how the character follows a source skeleton frame
by frame (:func:`motion.retarget.binding.bind`, the retargeting's own transfer measured once), and
:func:`character_model` the character's file to draw. Both are small and bounded (one rest pose,
at most :data:`schemas.characters.MAX_EXAMPLE_FRAMES` example frames of at most
:data:`schemas.characters.MAX_JOINTS` joints, the character's glTF JSON): the routes run them in a
worker thread of the API, a bounded number at once, as they parse bodies.
"""

from __future__ import annotations

import numpy as np

from motion import BvhLimits, Motion, MotionError, Skeleton
from motion.export.mannequin import mannequin_glb
from motion.retarget.binding import Binding, bind, own_binding, rest_motion
from motion.retarget.character import gltf_character
from motion.skeleton import default_channels
from schemas.characters import (
    BoundHips,
    BoundJoint,
    CharacterBinding,
    CharacterOf,
    CharacterRequest,
    ExampleFrames,
    SourceSkeleton,
)
from workers.result_export import CharacterRef, RestPose, RootMotion, character_of
from workers.store import NotFoundError, Store

from .deps import Principal
from .errors import ApiError
from .owners import clip_for, file_for

__all__ = [
    "CharacterRef",
    "RestPose",
    "RootMotion",
    "character_binding",
    "character_model",
    "character_ref",
    "source_skeleton",
]

GLTF_MEDIA_TYPES = {b"glTF": "model/gltf-binary"}
MIN_EXTENT_M = 0.01
"""The least a source skeleton's bone lengths may add up to (metres)."""
"""A character file's media type by its first bytes (``model/gltf+json`` otherwise)."""


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


def source_skeleton(body: SourceSkeleton) -> Skeleton:
    """The skeleton of a request (metres): 422 ``invalid_skeleton`` naming what is wrong."""
    j = len(body.names)
    if len(body.parents) != j or len(body.offsets) != j:
        raise ApiError(
            422,
            "invalid_skeleton",
            f"the skeleton has {j} names, {len(body.parents)} parents and {len(body.offsets)} offsets; "
            "give one of each per joint",
        )
    if any(site.parent >= j for site in body.end_sites):
        raise ApiError(422, "invalid_skeleton", f"an End Site's parent is not one of the {j} joints")
    try:
        skeleton = Skeleton(
            tuple(body.names),
            np.array(body.parents, dtype=np.intp),
            np.array(body.offsets, dtype=np.float64).reshape(j, 3),
            default_channels(j),
            np.array([s.parent for s in body.end_sites], dtype=np.intp),
            np.array([s.offset for s in body.end_sites], dtype=np.float64).reshape(-1, 3),
        )
    except MotionError as exc:
        raise ApiError(422, "invalid_skeleton", f"the skeleton is not a joint tree: {exc}") from None
    bones = np.linalg.norm(skeleton.offsets[1:], axis=1)
    if not bones.size or float(bones.sum()) < MIN_EXTENT_M:
        raise ApiError(
            422,
            "invalid_skeleton",
            f"the skeleton's bones add up to less than {100 * MIN_EXTENT_M:g} cm: it has no body to bind",
        )
    return skeleton


def _example(skeleton: Skeleton, frames: ExampleFrames) -> Motion:
    n, j = len(frames.root), skeleton.num_joints
    if len(frames.rotations) != n or any(len(r) != j for r in frames.rotations):
        raise ApiError(
            422,
            "invalid_skeleton",
            f"the example has {n} root positions: give as many frames of {j} rotations, one per joint",
        )
    q = np.array(frames.rotations, dtype=np.float64)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-6):
        raise ApiError(422, "invalid_skeleton", "an example rotation is not a quaternion (zero length)")
    return Motion(skeleton, np.array(frames.root, dtype=np.float64), q / norm, frames.fps, units="m")


def _character(
    store: Store, principal: Principal, ref: str, limits: BvhLimits
) -> tuple[CharacterOf, Motion, bytes | None]:
    """A named character in metres (its rest pose in frame 0) and, for a glTF file, its bytes."""
    found = character_ref(store, principal, ref)
    try:
        rest, raw = character_of(store, found, RestPose.first, limits)
    except MotionError as exc:
        raise ApiError(
            422, "not_a_character", f"{found.name} is not a character (a skinned glTF/GLB or a BVH): {exc}"
        ) from None
    return (
        CharacterOf(kind=found.kind, id=found.id, name=found.name),
        rest.scaled(rest.metres_per_unit, "m"),
        raw,
    )


def _binding_model(of: CharacterOf, b: Binding) -> CharacterBinding:
    doc = b.to_json()
    return CharacterBinding(
        character=of,
        source=doc["source"],
        target=doc["target"],
        joints=[BoundJoint(**j) for j in doc["joints"]],
        hips=BoundHips(**doc["hips"]),
    )


MANNEQUIN = CharacterOf(kind="mannequin", name="mannequin")


def _mannequin(skeleton: Skeleton) -> tuple[Motion, bytes]:
    """Segue's mannequin made on ``skeleton``: the rest it is made in (the zero pose) and its file."""
    rest = rest_motion(skeleton, "m")
    try:
        return rest, mannequin_glb(rest)
    except ValueError as exc:  # MotionError, or numbers the mesh cannot be made of
        raise ApiError(422, "invalid_skeleton", f"the mannequin cannot wear this skeleton: {exc}") from None


def character_binding(
    store: Store, principal: Principal, request: CharacterRequest, limits: BvhLimits
) -> CharacterBinding:
    """How the requested character follows the request's skeleton frame by frame (404 for a
    character the principal does not hold, 422 ``retarget_failed`` when the two skeletons do not
    correspond). Without a character, Segue's mannequin made on the skeleton itself: every joint
    follows itself (:func:`~motion.retarget.binding.own_binding`), no retargeting."""
    skeleton = source_skeleton(request.skeleton)
    example = None if request.example is None else _example(skeleton, request.example)
    if request.character is None:
        rest, raw = _mannequin(skeleton)
        try:
            return _binding_model(MANNEQUIN, own_binding(rest, gltf_character(raw)))
        except MotionError as exc:
            raise ApiError(
                422, "invalid_skeleton", f"the mannequin cannot wear this skeleton: {exc}"
            ) from None
    of, rest, _ = _character(store, principal, request.character, limits)
    try:
        b = bind(skeleton, rest, example=example)
    except ValueError as exc:  # MotionError, or numbers the transfer cannot use
        raise ApiError(422, "retarget_failed", f"{of.name} cannot follow this skeleton: {exc}") from None
    return _binding_model(of, b)


def character_model(
    store: Store, principal: Principal, request: CharacterRequest, limits: BvhLimits
) -> tuple[bytes, str]:
    """The requested character's file to draw and its media type: a glTF/GLB file as uploaded
    (422 ``not_a_character`` when it holds no skin), a BVH clip's skeleton wearing the mannequin,
    or (no character) the mannequin made on the request's skeleton."""
    if request.character is None:
        return _mannequin(source_skeleton(request.skeleton))[1], GLTF_MEDIA_TYPES[b"glTF"]
    of, rest, raw = _character(store, principal, request.character, limits)
    if raw is None:
        try:
            raw = mannequin_glb(rest)
        except ValueError as exc:  # MotionError, or numbers the mesh cannot be made of
            raise ApiError(422, "not_a_character", f"the mannequin cannot wear {of.name}: {exc}") from None
    return raw, GLTF_MEDIA_TYPES.get(raw[:4], "model/gltf+json")
