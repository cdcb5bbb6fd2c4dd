"""Plain-array exports: NPZ archives and JSON frames."""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..motion import Motion
from .targets import Target, get_target, to_target

Array = npt.NDArray[np.float64]


def motion_arrays(motion: Motion) -> dict[str, Any]:
    """The arrays of a motion for archiving (no pickled objects; strings as unicode arrays).

    Keys: ``positions (F, J, 3)`` global joint positions, ``rotations (F, J, 4)`` local quaternions
    (x, y, z, w), ``global_rotations (F, J, 4)``, ``root_positions (F, 3)``, ``offsets (J, 3)``,
    ``end_site_positions (F, E, 3)``, ``end_site_parents (E,)``, ``names (J,)``, ``parents (J,)``,
    ``fps`` and ``units`` (scalars).
    """
    pos, grot = motion.fk()
    return {
        "positions": np.ascontiguousarray(pos),
        "rotations": np.ascontiguousarray(motion.rotations),
        "global_rotations": np.ascontiguousarray(grot),
        "root_positions": motion.root_positions,
        "offsets": motion.skeleton.offsets,
        "end_site_positions": motion.end_site_positions(pos, grot),
        "end_site_parents": motion.skeleton.end_site_parents,
        "names": np.array(motion.skeleton.names, dtype=str),
        "parents": motion.skeleton.parents,
        "fps": np.float64(motion.fps),
        "units": np.array(motion.units),
    }


def npz_bytes(motion: Motion, target: str | Target = "gltf", units: str | None = None) -> bytes:
    """An NPZ archive of :func:`motion_arrays`.

    Unlike the other formats, an NPZ archive keeps the motion's own numbers (its ``units`` array
    says which unit) for the ``gltf``/``godot`` targets, so that it holds exactly what was read
    (the motion-core contract: ``positions`` equal the file's FK); ``units`` converts them, and
    ``unity``/``unreal`` convert to their axes and units (or ``units``).
    """
    tgt = get_target(target) if isinstance(target, str) else target
    if units is not None or tgt.name not in ("gltf", "godot"):
        motion = to_target(motion, tgt, units)
    buf = io.BytesIO()
    np.savez_compressed(buf, **motion_arrays(motion), target=np.array(tgt.name))
    return buf.getvalue()


def motion_json(
    motion: Motion,
    target: str | Target = "gltf",
    decimals: int = 5,
    units: str | None = None,
    events: Sequence[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """A JSON-ready dict: skeleton plus per-frame global positions and local rotations.

    Lengths in the target's units (metres for gltf/godot/unity, centimetres for unreal) or
    ``units`` when given; the motion's units must be known or are taken as metres. ``events``
    (:mod:`motion.export.events`, times in seconds) go in an ``"events"`` list when given.
    """
    tgt = get_target(target) if isinstance(target, str) else target
    moved = to_target(motion, tgt, units)
    pos = np.round(np.ascontiguousarray(moved.global_positions()), decimals)
    q = np.round(np.ascontiguousarray(moved.rotations), 6)
    sk = moved.skeleton
    out: dict[str, Any] = {
        "format": "segue.frames/1",
        "name": motion.name,
        "fps": motion.fps,
        "frame_count": motion.num_frames,
        "convention": {**tgt.describe(), "units": moved.units},
        "joints": list(sk.names),
        "parents": [int(p) for p in sk.parents],
        "offsets": np.round(sk.offsets, decimals).tolist(),
        "frames": [
            {"t": round(i / motion.fps, 6), "positions": p, "rotations": r}
            for i, (p, r) in enumerate(zip(pos.tolist(), q.tolist(), strict=True))
        ],
    }
    if events is not None:
        out["events"] = list(events)
    return out


def write_json(
    motion: Motion,
    path: str | Path,
    target: str | Target = "gltf",
    units: str | None = None,
    events: Sequence[dict[str, Any]] | None = None,
) -> None:
    """Write :func:`motion_json` compactly (one line) to ``path``."""
    text = json.dumps(motion_json(motion, target, units=units, events=events), separators=(",", ":"))
    Path(path).write_text(text, encoding="utf-8")


def write_npz(
    motion: Motion, path: str | Path, target: str | Target = "gltf", units: str | None = None
) -> None:
    """Write :func:`npz_bytes` to ``path``."""
    Path(path).write_bytes(npz_bytes(motion, target, units))
