"""Result downloads: a stored result motion in BVH, GLB, JSON frames or NPZ."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from enum import StrEnum
from typing import Any

from motion import ExportError, Motion
from motion.bvh import bvh_text
from motion.export.arrays import motion_json, npz_bytes
from motion.export.bind import bound_glb
from motion.export.events import contact_events_of, sorted_events
from motion.export.events import result_events as annotation_events
from motion.export.glb import glb_bytes
from motion.export.targets import to_target


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


MEDIA_TYPES: dict[ResultFormat, str] = {
    ResultFormat.bvh: "text/plain; charset=utf-8",
    ResultFormat.glb: "model/gltf-binary",
    ResultFormat.json: "application/json",
    ResultFormat.npz: "application/octet-stream",
}


def result_events(
    motion: Motion, annotations: Mapping[str, Any], kinds: Sequence[str], result_fps: float
) -> list[dict[str, Any]]:
    """The events of a result: foot contacts measured on ``motion`` (the motion exported, after
    any resampling) and the beats and labels of its report's ``annotations`` (label frame ranges
    at the result's own ``result_fps``), sorted by time."""
    evs = contact_events_of(motion) if "contacts" in kinds else []
    evs += annotation_events(annotations, result_fps, motion.duration_s, kinds)
    return sorted_events(evs)


class ExportUnits(StrEnum):
    """Length units of an export (default: the target's; GLB is always metres)."""

    m = "m"
    cm = "cm"
    mm = "mm"
    inch = "in"
    ft = "ft"


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
) -> bytes:
    """The file content of ``motion`` in ``fmt`` (raises :class:`motion.ExportError`).

    Lengths in the target's units (metres; centimetres for ``unreal``) unless ``units`` overrides
    them; GLB is metres. ``in_place`` is for GLB; ``events`` go into GLB extras and JSON frames.
    ``rig``: the glTF/GLB file of the character the motion was retargeted onto: a GLB is that file
    with the animation added (:func:`motion.export.bind.bound_glb`). ``ground_root=False`` keeps
    a GLB's skeleton exactly the motion's (a retargeted BVH character's hierarchy).
    """
    unit = None if units is None else units.value
    if in_place and fmt != ResultFormat.glb:
        raise ExportError("in_place is for format=glb (its ground joint keeps the root motion)")
    if events is not None and fmt not in (ResultFormat.glb, ResultFormat.json):
        raise ExportError("events go into format=glb (animation extras) and format=json only")
    if fmt == ResultFormat.glb:
        if unit not in (None, "m"):
            raise ExportError(f"GLB is in metres (glTF 2.0); units={unit} does not apply to it")
        if rig is not None:
            return bound_glb(rig, motion, events=events)
        return glb_bytes(motion, ground_root=ground_root, in_place=in_place, events=events)
    if fmt == ResultFormat.npz:
        return npz_bytes(motion, target.value, unit)
    if fmt == ResultFormat.json:
        doc = motion_json(motion, target.value, units=unit, events=events)
        return json.dumps(doc, separators=(",", ":")).encode()
    return bvh_text(to_target(motion, target.value, unit)).encode()
