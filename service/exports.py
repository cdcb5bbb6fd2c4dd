"""Result downloads: a stored result motion in BVH, GLB, JSON frames or NPZ."""

from __future__ import annotations

import json
from enum import StrEnum

from motion import Motion
from motion.bvh import bvh_text
from motion.export.arrays import motion_json, npz_bytes
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


def export_bytes(motion: Motion, fmt: ResultFormat, target: ExportTarget = ExportTarget.gltf) -> bytes:
    """The file content of ``motion`` in ``fmt`` (raises :class:`motion.ExportError`)."""
    if fmt == ResultFormat.glb:
        return glb_bytes(motion)
    if fmt == ResultFormat.npz:
        return npz_bytes(motion, target.value)
    if fmt == ResultFormat.json:
        return json.dumps(motion_json(motion, target.value), separators=(",", ":")).encode()
    out = motion if target in (ExportTarget.gltf, ExportTarget.godot) else to_target(motion, target.value)
    return bvh_text(out).encode()
