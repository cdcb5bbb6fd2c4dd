"""A held-out test character, not Segue's mannequin: a humanoid of its own proportions (short
legs, a long four-joint spine, long arms, big feet, a jaw, three-joint fingers and a thumb: 54
bones) whose body is a mesh fused from primitives and skinned by Blender's automatic weights
(``tests/tools/heldout_character.py``, Blender as a module), exported by Blender's glTF exporter
with Blender's own bone orientations. Its names are its own (``lf_pad``, ``rt_tip``: no preset
knows them); :func:`heldout_glb` renames the same file to Unreal's and Mixamo's conventions, and
:func:`heldout_role_map` is the ``--map`` a user writes for its own names, toes included.

Used by ``tests/integrations/test_heldout_feet.py`` and ``bench/feet_mesh.py``.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import tempfile
from pathlib import Path

from .namings import renamed_glb

TOOL = Path(__file__).resolve().parents[2] / "tools" / "heldout_character.py"
NAMINGS = ("unreal", "mixamo", "own")

_FINGERS = ("thumb", "index", "middle", "ring", "pinky")
_MIXAMO_FINGERS = ("Thumb", "Index", "Middle", "Ring", "Pinky")


def _bones() -> tuple[list[list[object]], dict[str, float]]:
    """``[name, parent, head, tail, roll_deg]`` (metres, Blender's axes: Z up, facing -Y, the
    character's left at +X) and each meshed bone's half-width."""
    bones: list[list[object]] = [
        ["cog", None, (0, 0.01, 0.90), (0, 0.0, 1.00), 0],
        ["spn_a", "cog", (0, 0.0, 1.00), (0, 0.005, 1.09), 0],
        ["spn_b", "spn_a", (0, 0.005, 1.09), (0, 0.01, 1.18), 0],
        ["spn_c", "spn_b", (0, 0.01, 1.18), (0, 0.015, 1.28), 0],
        ["spn_d", "spn_c", (0, 0.015, 1.28), (0, 0.01, 1.38), 0],
        ["nck", "spn_d", (0, 0.01, 1.40), (0, -0.005, 1.48), 0],
        ["skl", "nck", (0, -0.005, 1.48), (0, -0.01, 1.66), 0],
        ["jaw", "skl", (0, -0.02, 1.52), (0, -0.08, 1.50), 0],
    ]
    radius = {"cog": 0.15, "spn_a": 0.14, "spn_b": 0.14, "spn_c": 0.16, "spn_d": 0.15, "nck": 0.055}
    radius.update({"skl": 0.10, "jaw": 0.04})
    arm = (0.766, 0.0, -0.643)  # arms 40 degrees below the horizontal (an A pose)
    for s, sx in (("lf", 1.0), ("rt", -1.0)):

        def along(p: tuple[float, float, float], d: float, sx: float = sx) -> tuple[float, float, float]:
            return (p[0] + arm[0] * d * sx, p[1] + arm[1] * d, p[2] + arm[2] * d)

        shoulder = (0.19 * sx, 0.02, 1.37)
        elbow = along(shoulder, 0.31)
        wrist = along(elbow, 0.27)
        knuckles = along(wrist, 0.09)
        bones += [
            [f"{s}_clv", "spn_d", (0.025 * sx, -0.01, 1.36), (0.17 * sx, 0.02, 1.37), 0],
            [f"{s}_arm1", f"{s}_clv", shoulder, elbow, 20 * sx],
            [f"{s}_arm2", f"{s}_arm1", elbow, wrist, 20 * sx],
            [f"{s}_palm", f"{s}_arm2", wrist, knuckles, 20 * sx],
        ]
        radius.update({f"{s}_clv": 0.05, f"{s}_arm1": 0.055, f"{s}_arm2": 0.045, f"{s}_palm": 0.035})
        for k, finger in enumerate(_FINGERS):
            if finger == "thumb":
                base = (wrist[0] + 0.02 * sx, wrist[1] - 0.035, wrist[2] - 0.01)
                step = (0.45 * sx, -0.75, -0.48)
            else:
                base = (knuckles[0], knuckles[1] - 0.045 + 0.022 * k, knuckles[2])
                step = (arm[0] * sx, arm[1], arm[2])
            head = base
            for j, length in enumerate((0.04, 0.028, 0.022)):
                tail = (head[0] + step[0] * length, head[1] + step[1] * length, head[2] + step[2] * length)
                parent = f"{s}_palm" if j == 0 else f"{s}_f{k + 1}{'abc'[j - 1]}"
                name = f"{s}_f{k + 1}{'abc'[j]}"
                bones.append([name, parent, head, tail, 20 * sx])
                radius[name] = 0.012 if finger == "thumb" else 0.010
                head = tail
        bones += [
            [f"{s}_leg1", "cog", (0.10 * sx, 0.0, 0.88), (0.11 * sx, -0.01, 0.48), 0],
            [f"{s}_leg2", f"{s}_leg1", (0.11 * sx, -0.01, 0.48), (0.11 * sx, 0.01, 0.085), 0],
            [f"{s}_pad", f"{s}_leg2", (0.11 * sx, 0.01, 0.085), (0.12 * sx, -0.14, 0.025), 0],
            [f"{s}_tip", f"{s}_pad", (0.12 * sx, -0.14, 0.025), (0.12 * sx, -0.21, 0.025), 0],
        ]
        radius.update({f"{s}_leg1": 0.085, f"{s}_leg2": 0.06})  # feet and toes: boxes, flat soles
    return bones, radius


def _names() -> dict[str, dict[str, str]]:
    """Own name -> {"unreal": ..., "mixamo": ...}."""
    table = {
        "cog": ("pelvis", "Hips"),
        "spn_a": ("spine_01", "Spine"),
        "spn_b": ("spine_02", "Spine1"),
        "spn_c": ("spine_03", "Spine2"),
        "spn_d": ("spine_04", "Spine3"),
        "nck": ("neck_01", "Neck"),
        "skl": ("head", "Head"),
        "jaw": ("jaw", "Jaw"),
    }
    for s, side, word in (("lf", "l", "Left"), ("rt", "r", "Right")):
        table.update(
            {
                f"{s}_clv": (f"clavicle_{side}", f"{word}Shoulder"),
                f"{s}_arm1": (f"upperarm_{side}", f"{word}Arm"),
                f"{s}_arm2": (f"lowerarm_{side}", f"{word}ForeArm"),
                f"{s}_palm": (f"hand_{side}", f"{word}Hand"),
                f"{s}_leg1": (f"thigh_{side}", f"{word}UpLeg"),
                f"{s}_leg2": (f"calf_{side}", f"{word}Leg"),
                f"{s}_pad": (f"foot_{side}", f"{word}Foot"),
                f"{s}_tip": (f"ball_{side}", f"{word}ToeBase"),
            }
        )
        for k, (finger, mixamo) in enumerate(zip(_FINGERS, _MIXAMO_FINGERS, strict=True)):
            for j in range(3):
                table[f"{s}_f{k + 1}{'abc'[j]}"] = (f"{finger}_0{j + 1}_{side}", f"{word}Hand{mixamo}{j + 1}")
    return {own: {"unreal": u, "mixamo": f"mixamorig:{m}"} for own, (u, m) in table.items()}


BONES, RADIUS = _bones()
NAMES = _names()
UNREAL_TO_OWN = {n["unreal"]: own for own, n in NAMES.items()}


def name_of(naming: str, unreal: str) -> str:
    """The held-out character's joint called ``unreal`` in Unreal's naming, in ``naming``'s."""
    own = UNREAL_TO_OWN[unreal]
    return own if naming == "own" else NAMES[own][naming]


def heldout_role_map() -> dict[str, str]:
    """``{role: joint}`` for the character's own names, its toes included (a user's ``--map``)."""
    roles = {"Hips": "cog", "Head": "skl"}
    for s, side in (("lf", "Left"), ("rt", "Right")):
        for limb, own in (
            ("Shoulder", "clv"), ("UpperArm", "arm1"), ("LowerArm", "arm2"), ("Hand", "palm"),
            ("UpperLeg", "leg1"), ("LowerLeg", "leg2"), ("Foot", "pad"), ("Toes", "tip"),
        ):  # fmt: skip
            roles[f"{side}{limb}"] = f"{s}_{own}"
    return roles


def spec() -> dict[str, object]:
    """The build script's input (``tests/tools/heldout_character.py``)."""
    return {
        "bones": BONES,
        "radius": RADIUS,
        "feet": {"l": ["lf_pad", "lf_tip"], "r": ["rt_pad", "rt_tip"]},
        "foot_half_width": 0.05,
        "heel_behind_ankle": 0.06,
        "voxel": 0.008,
        "decimate": 0.35,
    }


def bpy_interpreter() -> Path | None:
    """Blender's Python: ``$SEGUE_BPY_PYTHON``, else tests/run.sh's default venv if it is there."""
    path = os.environ.get("SEGUE_BPY_PYTHON") or str(Path.home() / ".cache/segue/bpy-venv/bin/python")
    return Path(path) if Path(path).is_file() else None


def build_heldout(python: Path, folder: Path) -> bytes:
    """The character in its own names, built by Blender (``python``: Blender's Python) into
    ``folder`` (reused there while the build script and its input are unchanged)."""
    text = json.dumps(spec())
    key = hashlib.sha256(text.encode() + TOOL.read_bytes()).hexdigest()[:12]
    out = folder / f"heldout-{key}.glb"
    if not out.is_file():
        with tempfile.TemporaryDirectory() as tmp:
            spec_file = Path(tmp) / "bones.json"
            spec_file.write_text(text)
            env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
            res = subprocess.run(
                [str(python), str(TOOL), "--", str(spec_file), str(Path(tmp) / "c.glb")],
                capture_output=True, text=True, timeout=600, check=False, env=env,
            )  # fmt: skip
            made = Path(tmp) / "c.glb"
            if not made.is_file():
                log = f"{res.stdout[-2000:]}\n{res.stderr[-2000:]}"
                raise RuntimeError(f"Blender did not build the character:\n{log}")
            made.replace(out)
    return out.read_bytes()


def heldout_glb(own: bytes, naming: str) -> bytes:
    """The character file ``own`` (its own names) with its joints renamed to ``naming``."""
    if naming == "own":
        return own
    return renamed_glb(own, naming, lambda n: NAMES[n][naming] if n in NAMES else n)
