"""Reading and writing motions by file extension.

Input: ``.bvh`` and ``.bvh.gz`` (:mod:`motion.bvh`), ``.glb`` and ``.gltf`` (one animation of a
skinned glTF file, :mod:`motion.gltf`). Output: ``.bvh`` (``.bvh.gz``), ``.glb``, ``.json``,
``.npz``. :func:`parse_motion` reads bytes of either input format, told apart by their content.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .bvh import BvhLimits, parse_bvh, write_bvh
from .errors import ExportError, GltfError, MotionError, ReadWarning
from .export.arrays import write_json, write_npz
from .export.events import contact_events_of, sorted_events
from .export.targets import get_target, output_units, to_target
from .motion import Motion
from .samples import declared_units, resolve_path

INPUT_SUFFIXES = (".bvh", ".bvh.gz", ".glb", ".gltf")
OUTPUT_SUFFIXES = (".bvh", ".bvh.gz", ".glb", ".json", ".npz")


def _suffix(path: Path, allowed: tuple[str, ...]) -> str:
    name = path.name.lower()
    for s in sorted(allowed, key=len, reverse=True):
        if name.endswith(s):
            return s
    raise MotionError(f"{path}: unsupported file type; expected one of {', '.join(allowed)}")


def load_motion(
    path: str | Path,
    *,
    units: str | None = None,
    limits: BvhLimits | None = None,
    animation: str | int | None = None,
    warnings: list[ReadWarning] | None = None,
) -> Motion:
    """Read a motion file (BVH, optionally gzip-compressed; a glTF/GLB file's animation;
    ``sample:NAME`` for a bundled sample); see :func:`parse_motion`. ``units`` None: a bundled
    sample in the unit the catalogue declares (:data:`motion.samples.SAMPLE_UNITS`), any other
    BVH file in its guessed unit, glTF in metres."""
    p = resolve_path(path)
    _suffix(p, INPUT_SUFFIXES)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise MotionError(f"{p}: cannot read file: {exc.strerror or exc}") from None
    stem = p.name
    for suffix in (".gz", ".bvh", ".glb", ".gltf"):
        stem = stem.removesuffix(suffix)
    return parse_motion(
        data,
        units=units if units is not None else declared_units(p),
        limits=limits,
        source=str(p),
        name=stem,
        animation=animation,
        warnings=warnings,
        base_dir=p.parent,
    )


def parse_motion(
    data: bytes,
    *,
    units: str | None = None,
    limits: BvhLimits | None = None,
    source: str = "<bytes>",
    name: str = "",
    animation: str | int | None = None,
    warnings: list[ReadWarning] | None = None,
    base_dir: str | Path | None = None,
) -> Motion:
    """A motion from the bytes of a BVH file (plain or gzip) or of a glTF file (GLB, or ``.gltf``
    JSON with its buffers inline or in ``base_dir``), told apart by content.

    ``units``: a BVH file's declared unit (default: guessed); a glTF file is in metres (any other
    unit is an error). ``animation``: which animation of a glTF file (name or index; default the
    first; an error for BVH, which holds one). ``name``: the motion's name (a glTF animation's own
    name when empty). ``warnings``: when given, the departures from the format the reader accepted
    (:class:`~motion.errors.ReadWarning`) are appended to it. Raises :class:`MotionError` (a
    :class:`~motion.errors.BvhError` for BVH) naming ``source``."""
    from .gltf import is_gltf

    if is_gltf(data):
        try:
            return _gltf_motion(data, units, limits, animation, name, source, warnings, base_dir)
        except GltfError:
            raise
        except MotionError as exc:  # every fault of a glTF input is named as one (400 invalid_gltf)
            raise GltfError(str(exc)) from None
    if animation is not None:
        raise MotionError(f"{source}: a BVH file holds one motion; 'animation' is for glTF files")
    return parse_bvh(data, units=units, limits=limits, source=source, name=name, warnings=warnings)


def _gltf_motion(
    data: bytes,
    units: str | None,
    limits: BvhLimits | None,
    animation: str | int | None,
    name: str,
    source: str,
    warnings: list[ReadWarning] | None,
    base_dir: str | Path | None,
) -> Motion:
    """:func:`parse_motion` of a glTF file."""
    from .gltf import parse_gltf

    if units not in (None, "m"):
        raise MotionError(f"{source}: a glTF file is in metres (glTF's rule); units {units!r} do not apply")
    lim = limits or BvhLimits()
    motion = parse_gltf(
        data,
        animation=animation,
        name=name or None,
        source=source,
        base_dir=base_dir,
        max_joints=lim.max_joints,
        max_joint_frames=lim.max_joint_frames,
        warnings=warnings,
    )
    if motion.num_frames > lim.max_frames:
        raise MotionError(f"{source}: {motion.num_frames} frames is over the {lim.max_frames}-frame limit")
    return motion


def save_motion(
    motion: Motion,
    path: str | Path,
    *,
    target: str = "gltf",
    units: str | None = None,
    in_place: bool = False,
    events: Sequence[str] = (),
    extra_events: Sequence[dict[str, Any]] = (),
) -> list[str]:
    """Write a motion in the format given by the extension of ``path``.

    Parameters
    ----------
    target:
        Axis/unit convention (``gltf``, ``godot``, ``unity``, ``unreal``) for BVH, JSON and NPZ.
        GLB is always glTF's own convention (right-handed, Y up, metres), which every engine's
        glTF importer converts itself; a different target is noted, not applied.
    units:
        Override of the length unit of BVH, JSON and NPZ (default: the target's, metres for
        gltf/godot/unity and centimetres for unreal). GLB is metres: any other unit is an error.
    in_place:
        GLB only: the body stays over the origin, the root motion is on the ``ground`` joint.
    events:
        Kinds of events measured on the motion (``"contacts"``) written with ``extra_events``
        (e.g. a result's beats and labels) into GLB ``extras`` and the JSON ``events``.

    Returns
    -------
    Notes for the user (empty when there is nothing to say).
    """
    p = Path(path)
    kind = _suffix(p, OUTPUT_SUFFIXES)
    tgt = get_target(target)
    output_units(tgt, units)  # an unknown unit fails here, before anything is written
    notes: list[str] = []
    if in_place and kind != ".glb":
        raise ExportError("in-place export is for .glb (its ground joint keeps the root motion)")
    wanted = [*(contact_events_of(motion) if "contacts" in events else []), *extra_events]
    if (events or extra_events) and kind not in (".glb", ".json"):
        raise ExportError("events go into .glb (animation extras) and .json (events) files only")
    evs = sorted_events(wanted) if (events or extra_events) else None
    if kind == ".glb":
        from .export.glb import write_glb

        if units is not None and units != "m":
            raise ExportError(f"GLB is in metres (glTF 2.0); --units {units} does not apply to it")
        if tgt.name not in ("gltf", "godot"):
            notes.append(
                f"GLB is always written in glTF convention (right-handed, Y up, metres); {tgt.name}'s glTF "
                "importer converts it on import, so --target does not apply"
            )
        write_glb(motion, p, in_place=in_place, events=evs)
    elif kind == ".npz":
        write_npz(motion, p, tgt, units)
    elif kind == ".json":
        write_json(motion, p, tgt, units, evs)
    else:
        write_bvh(to_target(motion, tgt, units), p)
    return notes
