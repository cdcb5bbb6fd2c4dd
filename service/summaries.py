"""What the command line and the demos print of a motion file and of a result: the facts of
``segue inspect`` and a result's quality in a few lines."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from motion import Motion
    from schemas import Report


def inspect_summary(path: Path, motion: Motion, declared: str | None, up: str = "auto") -> dict[str, Any]:
    """The facts ``segue inspect`` reports, JSON-ready. ``declared``: the unit the user gave (else
    the sample catalogue's, :func:`motion.samples.declared_units`, else guessed); ``up``: ``y``,
    ``z`` or ``auto`` (detected: :func:`motion.units.up_axis`). ``height_m`` is Segue's one height
    (:func:`motion.bvh.height_m`: the standing height over the motion's frames; a glTF file without
    animation: its bind pose), the same for a BVH file and its GLB."""
    from motion.bvh import detect_units, detect_up_axis
    from motion.samples import declared_units
    from motion.units import METRES_PER_UNIT

    axis = {"y": 1, "z": 2}.get(up) or detect_up_axis(motion)
    guess = detect_units(motion, axis)
    frames, fps = motion.num_frames, motion.fps
    source = "declared" if declared else "sample" if declared_units(path) else "guess"
    if path.name.lower().endswith((".glb", ".gltf")):
        source = "gltf"  # metres, by glTF's rule
    # a guessed unit comes from the height along the up axis (the reader guessed it along Y)
    units = guess.units if source == "guess" else motion.units
    mpu = METRES_PER_UNIT.get(units, motion.metres_per_unit)
    return {
        "file": str(path),
        "name": motion.name,
        "frames": frames,
        "fps": fps,
        "duration_s": round(motion.duration_s, 6),
        "joints": list(motion.skeleton.names),
        "parents": [int(p) for p in motion.skeleton.parents],
        "channels": motion.skeleton.num_channels,
        "end_sites": int(motion.skeleton.end_site_parents.size),
        "units": units,
        "units_source": source,
        "up": "yz"[axis - 1],
        "up_source": "declared" if up != "auto" else "detected",
        "height": round(guess.height, 6),
        "height_m": round(guess.height * mpu, 4),
        "units_guess": {
            "units": guess.units,
            "height_m": round(guess.height_m, 4),
            "plausible": guess.plausible,
        },
    }


def count(n: int, noun: str) -> str:
    """``n`` and the noun, plural unless one: ``count(1, "clip")`` is ``"1 clip"``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def quality_summary(report: Report) -> str:
    """One line per reason a result is not ok (``quality: ok`` when it is)."""
    if report.ok is None:
        return "quality: not measured"
    if report.ok:
        return "quality: ok (every constraint met, plausible against the database's examples)"
    return "quality: NOT ok\n" + "\n".join(f"  - {r}" for r in report.reasons)
