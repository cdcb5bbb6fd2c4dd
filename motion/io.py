"""Reading and writing motions by file extension.

Input: ``.bvh`` and ``.bvh.gz``. Output: ``.bvh`` (``.bvh.gz``), ``.glb``, ``.json``, ``.npz``.
"""

from __future__ import annotations

from pathlib import Path

from .bvh import BvhLimits, read_bvh, write_bvh
from .errors import ExportError, MotionError
from .export.arrays import write_json, write_npz
from .export.targets import get_target, to_target
from .motion import Motion
from .samples import resolve_path

INPUT_SUFFIXES = (".bvh", ".bvh.gz")
OUTPUT_SUFFIXES = (".bvh", ".bvh.gz", ".glb", ".json", ".npz")


def _suffix(path: Path, allowed: tuple[str, ...]) -> str:
    name = path.name.lower()
    for s in sorted(allowed, key=len, reverse=True):
        if name.endswith(s):
            return s
    raise MotionError(f"{path}: unsupported file type; expected one of {', '.join(allowed)}")


def load_motion(path: str | Path, *, units: str | None = None, limits: BvhLimits | None = None) -> Motion:
    """Read a motion file (BVH, optionally gzip-compressed; ``sample:NAME`` for a bundled sample);
    see :func:`motion.bvh.read_bvh`."""
    p = resolve_path(path)
    _suffix(p, INPUT_SUFFIXES)
    return read_bvh(p, units=units, limits=limits)


def save_motion(
    motion: Motion, path: str | Path, *, target: str = "gltf", units: str | None = None
) -> list[str]:
    """Write a motion in the format given by the extension of ``path``.

    Parameters
    ----------
    target:
        Axis/unit convention (``gltf``, ``godot``, ``unity``, ``unreal``) for BVH, JSON and NPZ.
        GLB is always glTF's own convention (right-handed, Y up, metres), which every engine's
        glTF importer converts itself; a different target is noted, not applied.
    units:
        For BVH and NPZ with the ``gltf``/``godot`` target: the length unit to write (default:
        the motion's own).

    Returns
    -------
    Notes for the user (empty when there is nothing to say).
    """
    p = Path(path)
    kind = _suffix(p, OUTPUT_SUFFIXES)
    tgt = get_target(target)
    notes: list[str] = []
    if kind == ".glb":
        from .export.glb import write_glb

        if tgt.name not in ("gltf", "godot"):
            notes.append(
                f"GLB is always written in glTF convention (right-handed, Y up, metres); {tgt.name}'s glTF "
                "importer converts it on import, so --target does not apply"
            )
        write_glb(motion, p)
    elif kind == ".npz":
        write_npz(motion, p, tgt, units)
    elif kind == ".json":
        if units is not None:
            notes.append("JSON frames use the target's units; --units does not apply")
        write_json(motion, p, tgt)
    else:
        out = to_target(motion, tgt) if tgt.name not in ("gltf", "godot") else motion
        if units is not None and tgt.name in ("gltf", "godot"):
            out = out.to_units(units)
        elif units is not None:
            raise ExportError(f"--units cannot be combined with --target {tgt.name} (it fixes the units)")
        write_bvh(out, p)
    return notes
