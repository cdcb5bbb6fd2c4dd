"""A result's download: the stored motion, optionally retargeted onto a character and resampled,
in BVH, GLB, JSON frames or NPZ (what ``GET /v1/jobs/{id}/result`` answers).

:class:`ExportSpec` is the whole question (the result, the format and every option, the character
resolved to an upload id); :meth:`ExportSpec.key` names its answer in the store, so each export is
made once (:func:`make_export`) and then streamed. :func:`make_export` runs where the work is
allowed: in a worker as a small job (:mod:`workers.tasks`), or in the API when
:func:`inline_ok` says the result is small.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from enum import StrEnum
from typing import Any

import numpy as np

from motion import BvhLimits, ExportError, Motion, MotionError
from motion.bvh import bvh_text
from motion.export.arrays import motion_json, npz_bytes
from motion.export.bind import bound_glb
from motion.export.events import contact_events_of, parse_kinds, sorted_events
from motion.export.events import result_events as annotation_events
from motion.export.glb import MeshKind, glb_bytes
from motion.export.targets import to_target
from schemas.common import FeetMode

from .store import Store


class ResultFormat(StrEnum):
    """Download formats of a result."""

    bvh = "bvh"
    glb = "glb"
    json = "json"
    npz = "npz"


class ExportTarget(StrEnum):
    """Axis/unit conventions (GLB is always glTF's own)."""

    gltf = "gltf"
    godot = "godot"
    unity = "unity"
    unreal = "unreal"


class ExportUnits(StrEnum):
    """Length units of an export (default: the target's; GLB is always metres)."""

    m = "m"
    cm = "cm"
    mm = "mm"
    inch = "in"
    ft = "ft"


class ResultMesh(StrEnum):
    """The skinned mesh a GLB download carries (a glTF character's own mesh replaces it): the bone
    octahedra, Segue's mannequin (:mod:`motion.export.mannequin`) or none."""

    bones = "bones"
    body = "body"
    none = "none"


class RestPose(StrEnum):
    """A BVH character's rest pose: its first frame or the zero-rotation pose of its offsets."""

    first = "first"
    zero = "zero"


class RootMotion(StrEnum):
    """Where a retargeted result's root motion goes (:mod:`motion.retarget.rootmotion`)."""

    root = "root"
    hips = "hips"
    none = "none"


MEDIA_TYPES: dict[ResultFormat, str] = {
    ResultFormat.bvh: "text/plain; charset=utf-8",
    ResultFormat.glb: "model/gltf-binary",
    ResultFormat.json: "application/json",
    ResultFormat.npz: "application/octet-stream",
}

INLINE_JOINT_FRAMES = 200_000
"""Largest export (output frames x joints) an API process makes itself: ~10 MB of arrays, tens of
milliseconds; a viewer's previews and most downloads. Larger ones, and every retargeting, run in a
worker (0: all of them)."""


class ExportFailure(Exception):
    """An export that cannot be made: HTTP ``status``, error ``code`` and a message."""

    def __init__(self, status: int, code: str, message: str) -> None:
        super().__init__(message)
        self.status, self.code, self.message = status, code, message


@dataclass(frozen=True, slots=True)
class CharacterRef:
    """A character resolved to an upload: a BVH clip (``kind="clip"``, in ``units``) or a glTF/GLB
    file (``kind="file"``); ``name`` as uploaded, ``ref`` as the request named it."""

    kind: str
    id: str
    name: str
    ref: str
    units: str | None = None


@dataclass(frozen=True, slots=True)
class ExportSpec:
    """One download of a result (the query of ``GET /v1/jobs/{id}/result``; ``character`` resolved).

    ``max_frames`` and ``max_joint_frames`` bound a resampling (the server's ``max_output_frames``
    and ``max_joint_frames``); ``bvh_limits`` reads a BVH character. ``feet`` (``None``: lock with
    a character, free without) is what happens to the feet (:data:`schemas.common.FeetMode`)."""

    job: str
    result: str
    format: ResultFormat = ResultFormat.bvh
    target: ExportTarget = ExportTarget.gltf
    fps: float | None = None
    max_fps: float | None = None
    character: CharacterRef | None = None
    rest: RestPose = RestPose.first
    units: ExportUnits | None = None
    in_place: bool = False
    root_motion: RootMotion | None = None
    events: str | None = None
    mesh: ResultMesh = ResultMesh.bones
    animation_only: bool = False
    dancer: int | None = None
    feet: FeetMode | None = None
    max_frames: int = 36_000
    max_joint_frames: int = 10_000_000
    bvh_limits: tuple[int, int, int] = (1024, 2_000_000, 1 << 30)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form (a small job's payload)."""
        out = asdict(self)
        out["bvh_limits"] = list(self.bvh_limits)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ExportSpec:
        d = dict(data)
        char = d.get("character")
        return cls(
            job=str(d["job"]),
            result=str(d["result"]),
            format=ResultFormat(d["format"]),
            target=ExportTarget(d["target"]),
            fps=d.get("fps"),
            max_fps=d.get("max_fps"),
            character=CharacterRef(**char) if char else None,
            rest=RestPose(d["rest"]),
            units=None if d.get("units") is None else ExportUnits(d["units"]),
            in_place=bool(d["in_place"]),
            root_motion=None if d.get("root_motion") is None else RootMotion(d["root_motion"]),
            events=d.get("events"),
            mesh=ResultMesh(d.get("mesh", ResultMesh.bones)),
            animation_only=bool(d.get("animation_only", False)),
            dancer=None if d.get("dancer") is None else int(d["dancer"]),
            feet=None if d.get("feet") is None else FeetMode(d["feet"]),
            max_frames=int(d["max_frames"]),
            max_joint_frames=int(d["max_joint_frames"]),
            bvh_limits=(int(d["bvh_limits"][0]), int(d["bvh_limits"][1]), int(d["bvh_limits"][2])),
        )

    def key(self) -> str:
        """The export's name in the store: its result, format and a digest of every option (the
        options added later, at their defaults, are left out: earlier exports keep their keys)."""
        options = {k: v for k, v in self.to_dict().items() if k not in ("job", "result")}
        if options["animation_only"] is False:
            del options["animation_only"]
        if options["dancer"] is None:
            del options["dancer"]
        if self.mesh == ResultMesh.bones:
            del options["mesh"]
        if options["feet"] is None:
            del options["feet"]
        digest = hashlib.sha256(json.dumps(options, sort_keys=True).encode()).hexdigest()[:24]
        return f"{self.result}-{digest}-{self.format.value}".lower()

    def output_fps(self, fps: float) -> float | None:
        """The rate the result (at ``fps``) is resampled to, None when it is not."""
        out = self.fps
        if out is None and self.max_fps is not None and fps > self.max_fps:
            out = self.max_fps
        return out


def inline_ok(spec: ExportSpec, frames: int, joints: int, fps: float) -> bool:
    """True when an export of a result of ``frames`` x ``joints`` at ``fps`` is small enough to
    make in the API process (:data:`INLINE_JOINT_FRAMES`; never with a character or a foot
    clean-up)."""
    if spec.character is not None or spec.feet not in (None, FeetMode.free):
        return False
    out_fps = spec.output_fps(fps) or fps
    return frames * max(out_fps / fps, 1.0) * joints <= INLINE_JOINT_FRAMES


def result_events(
    motion: Motion, annotations: Mapping[str, Any], kinds: Sequence[str], result_fps: float
) -> list[dict[str, Any]]:
    """The events of a result: foot contacts measured on ``motion`` (the motion exported, after
    any resampling) and the beats and labels of its report's ``annotations`` (label frame ranges
    at the result's own ``result_fps``), sorted by time."""
    evs = contact_events_of(motion) if "contacts" in kinds else []
    evs += annotation_events(annotations, result_fps, motion.duration_s, kinds)
    return sorted_events(evs)


def export_bytes(
    motion: Motion,
    fmt: ResultFormat,
    target: ExportTarget = ExportTarget.gltf,
    *,
    units: ExportUnits | None = None,
    in_place: bool = False,
    events: Sequence[dict[str, Any]] | None = None,
    rig: bytes | None = None,
    ground_root: bool = True,
    mesh: ResultMesh = ResultMesh.bones,
    animation_only: bool = False,
) -> bytes:
    """The file content of ``motion`` in ``fmt`` (raises :class:`motion.ExportError`).

    Lengths in the target's units (metres; centimetres for ``unreal``) unless ``units`` overrides
    them; GLB is metres. ``in_place`` is for GLB; ``events`` go into GLB extras and JSON frames.
    ``rig``: the glTF/GLB file of the character the motion was retargeted onto: a GLB is that file
    with the animation added (:func:`motion.export.bind.bound_glb`), or with ``animation_only``
    just its skeleton and the animation. ``ground_root=False`` keeps a GLB's skeleton exactly the
    motion's (a retargeted BVH character's hierarchy). ``mesh``: what a GLB without ``rig`` wears
    (:class:`ResultMesh`).
    """
    unit = None if units is None else units.value
    if in_place and fmt != ResultFormat.glb:
        raise ExportError("in_place is for format=glb (its ground joint keeps the root motion)")
    if animation_only and (fmt != ResultFormat.glb or rig is None):
        raise ExportError("animation_only is for format=glb onto a glTF/GLB character")
    if events is not None and fmt not in (ResultFormat.glb, ResultFormat.json):
        raise ExportError("events go into format=glb (animation extras) and format=json only")
    if fmt == ResultFormat.glb:
        if unit not in (None, "m"):
            raise ExportError(f"GLB is in metres (glTF 2.0); units={unit} does not apply to it")
        if rig is not None:
            return bound_glb(rig, motion, animation_only=animation_only, events=events)
        shapes: dict[ResultMesh, MeshKind | bool] = {ResultMesh.bones: "bones", ResultMesh.body: "body"}
        shape = shapes.get(mesh, False)
        return glb_bytes(motion, ground_root=ground_root, in_place=in_place, events=events, mesh=shape)
    if fmt == ResultFormat.npz:
        return npz_bytes(motion, target.value, unit)
    if fmt == ResultFormat.json:
        doc = motion_json(motion, target.value, units=unit, events=events)
        return json.dumps(doc, separators=(",", ":")).encode()
    return bvh_text(to_target(motion, target.value, unit)).encode()


def character_of(
    store: Store, ref: CharacterRef, rest: RestPose, limits: BvhLimits
) -> tuple[Motion, bytes | None]:
    """A character's rest pose (a one-frame motion) and, for a glTF/GLB file, the file itself.

    A BVH character's first frame is parsed from the file's head only
    (:func:`motion.bvh_header.bvh_first_frames`): the same frame, without reading the others."""
    from motion import BvhError
    from motion.bvh import parse_bvh
    from motion.bvh_header import bvh_first_frames
    from motion.gltf import is_gltf
    from motion.retarget.character import gltf_character
    from motion.retarget.transfer import zero_pose

    if ref.kind == "file":
        raw = store.file_bytes(ref.id)
        return gltf_character(raw, name=ref.name), raw
    data = store.clip_bytes(ref.id)
    if is_gltf(data):  # a glTF clip: its skin's bind pose, as a glTF file character
        return gltf_character(data, name=ref.name), data
    motion: Motion | None = None
    head = bvh_first_frames(data, 1, ref.name)
    if head is not None:
        try:
            motion = parse_bvh(head, units=ref.units, limits=limits, source=ref.name, name=ref.name)
        except BvhError:
            motion = None  # e.g. blank lines before the first frame: read it all
    if motion is None:
        motion = parse_bvh(data, units=ref.units, limits=limits, source=ref.name, name=ref.name)
    return (zero_pose(motion) if rest == RestPose.zero else motion.slice(0, 1)), None


def make_export(store: Store, spec: ExportSpec) -> bytes:
    """The bytes of ``spec``'s download (the computation ``GET .../result`` always answered with).

    Raises :class:`ExportFailure`: 422 ``retarget_failed`` (the character's joints do not
    correspond), 422 ``export_failed`` (numbers that are not finite, an option the format does not
    take), 413 ``too_large`` (a resampling past the server's frame limits); ``NotFoundError`` for a
    result or character that is gone."""
    motion = store.result_motion(spec.job, spec.result)
    rid, fmt, units, in_place = spec.result, spec.format, spec.units, spec.in_place
    if spec.dancer is not None:
        motion = _dancer(motion, spec.dancer, rid)
    rig: bytes | None = None
    if spec.character is not None:
        from motion.export.characters import split_characters
        from motion.retarget import correspond, retarget
        from motion.retarget.rootmotion import default_root_motion
        from motion.skinning import read_skinned_mesh

        dancers = split_characters(motion)
        if dancers is not None and len(dancers) > 1:
            raise ExportFailure(
                422,
                "export_failed",
                f"result {rid} has {len(dancers)} dancers; a character wears one: download each "
                f"with dancer=0..{len(dancers) - 1} and character={spec.character.ref}",
            )
        limits = BvhLimits(*spec.bvh_limits)
        char, rig = character_of(store, spec.character, spec.rest, limits)
        mode = "none" if in_place else None if spec.root_motion is None else spec.root_motion.value
        in_place = False  # a character's root motion is placed by the retargeting
        try:
            hips = correspond(motion.skeleton, char.skeleton).target_roles["Hips"]
            mesh = None if rig is None else read_skinned_mesh(rig)  # its soles stand on the floor
            motion = retarget(
                motion,
                char,
                root_motion=mode or default_root_motion(spec.target.value, hips),
                feet=(spec.feet or FeetMode.lock).value,
                mesh=mesh,
            )
        except MotionError as exc:
            raise ExportFailure(
                422, "retarget_failed", f"cannot retarget result {rid} onto {spec.character.ref}: {exc}"
            ) from None
        if units is None and fmt is not ResultFormat.glb and motion.units in {u.value for u in ExportUnits}:
            units = ExportUnits(motion.units)  # the character's own units, exactly
    elif spec.feet is not None and spec.feet is not FeetMode.free:
        from motion.retarget.legik import feet_on_floor

        try:
            motion = feet_on_floor(motion, spec.feet.value)
        except MotionError as exc:
            raise ExportFailure(
                422, "export_failed", f"cannot keep the feet of result {rid} on the floor: {exc}"
            ) from None
    if not (np.isfinite(motion.root_positions).all() and np.isfinite(motion.rotations).all()):
        raise ExportFailure(
            422, "export_failed", f"result {rid} holds numbers that are not finite; it cannot be exported"
        )
    result_fps = motion.fps
    try:
        fps = spec.output_fps(motion.fps)
        if fps is not None:
            _check_resampling(spec, motion, fps)
        if fps is not None and abs(fps - motion.fps) > 1e-9:
            from motion.resample import resample

            motion = resample(motion, fps)
        kinds = parse_kinds(spec.events) if spec.events else ()
        evs = None
        if kinds:
            annotations = store.result_report(spec.job, rid).annotations
            evs = result_events(motion, annotations, kinds, result_fps)
        return export_bytes(
            motion,
            fmt,
            spec.target,
            units=units,
            in_place=in_place,
            events=evs,
            rig=rig,
            ground_root=spec.character is None,
            mesh=spec.mesh,
            animation_only=spec.animation_only,
        )
    except (ExportError, MotionError) as exc:
        raise ExportFailure(
            422, "export_failed", f"cannot export result {rid} as {fmt.value}: {exc}"
        ) from None


def _dancer(motion: Motion, dancer: int, rid: str) -> Motion:
    """Dancer ``dancer`` of a result of several (a crowd, a couple, several graph characters: one
    subtree per dancer under the ``world`` root, :mod:`motion.export.characters`), its joints
    without their ``c0_`` prefix; 422 ``export_failed`` when the result has no such dancer."""
    from motion.export.characters import split_characters, without_prefix

    dancers = split_characters(motion) or [motion]
    if not 0 <= dancer < len(dancers):
        raise ExportFailure(
            422,
            "export_failed",
            f"result {rid} has {len(dancers)} dancer{'s' if len(dancers) != 1 else ''} "
            f"(0..{len(dancers) - 1}), not dancer {dancer}",
        )
    one, _ = without_prefix(dancers[dancer])
    return replace(one, name=motion.name)


def _check_resampling(spec: ExportSpec, motion: Motion, fps: float) -> None:
    """413 when resampling to ``fps`` gives more than 4 x the frame limit (or the result's own
    frames), or more joint-frames than the job limit (or the result's own)."""
    frames = motion.num_frames * fps / motion.fps
    most = 4 * max(spec.max_frames, motion.num_frames)
    if frames > most:
        raise ExportFailure(
            413,
            "too_large",
            f"resampling result {spec.result} ({motion.num_frames} frames at {motion.fps:g} fps) to "
            f"{fps:g} fps would give over {most} frames",
        )
    joints = motion.skeleton.num_joints
    most_jf = max(spec.max_joint_frames, motion.num_frames * joints)
    if frames * joints > most_jf:
        raise ExportFailure(
            413,
            "too_large",
            f"resampling result {spec.result} ({motion.num_frames} frames x {joints} joints at "
            f"{motion.fps:g} fps) to {fps:g} fps would give {frames * joints:.0f} joint-frames, over "
            f"{most_jf} (SEGUE_MAX_JOINT_FRAMES)",
        )
