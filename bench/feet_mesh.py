"""Benchmark: feet on the floor, measured on the character's own skinned mesh.

A suite of retargets (``segue retarget SOURCE --to CHARACTER.glb --out OUT.glb --events
contacts``, the command line a user runs) onto skinned characters, each measured on the file
written, as Blender or a game engine plays it: the character's mesh deformed by linear blend
skinning (numpy, :mod:`motion.skinning`; ``tests/motion/test_feet_blender.py`` checks it against
Blender's own deformation) under the animation in the output file.

Sources: ``sample:walk``, the rhythm demo's dance (``segue demo rhythm``: the salsa leader to the
bundled MIDI song, 120 fps) and, when ``../shared/data`` is there, Bandai-Namco's short dance and a
CMU salsa leader. Characters: Segue's mannequin (:mod:`motion.export.mannequin`: a heel behind the
ankle, a ball, toes, soles flat on the rest floor) on the test game rig's skeleton
(``tests/motion/retarget/namings.py``: Unreal-style, a root, ball joints) and on a Bandai-Namco
skeleton (its first frame: a rest pose taken from a clip), each under Unreal names, Mixamo names
and names of its own with a role map naming every role, toes included (a checkout whose maps
cannot name toes the source lacks gets the map without them: ``map_toes`` false).

Per retarget (all on the output file):

* ``sink_cm``: how far the mesh goes under its rest floor (the lowest vertex of the bind pose), at
  worst (``sink_frame``);
* ``lift_cm``: over the frames of the file's contact events, how far the planted foot's lowest
  vertex (vertices weighted at least half to that foot and its toes) is above the rest floor, at
  worst (``lift_frame``), and ``lift_p95_cm`` its 95th percentile;
* ``foot_speed_ratio``: the fastest foot joint (ankle or toe, world speed frame to frame) over the
  source's fastest (ankle or toe) scaled by the leg-length ratio (character over source, thigh plus
  shin in the rest poses), with ``foot_speed_m_s`` and its frame and joint;
* ``contacts``: contact events in the file, and ``contacts_per_plant`` per plant of the source
  (:func:`motion.contacts.foot_plants` on the source's feet).

``--code DIR`` retargets with another checkout's command line (e.g. main as it was, unpacked with
``git archive COMMIT | tar -x -C DIR``): the measurement is this checkout's. ``--keep DIR`` keeps
the characters and outputs (for pictures: ``bench/feet_pictures.py``). Prints one JSON object:
every row and the worst of each figure per source.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from motion import Motion  # noqa: E402
from motion.export.mannequin import mannequin_glb  # noqa: E402
from motion.io import load_motion  # noqa: E402
from motion.refpose import without_reference_lead  # noqa: E402
from motion.retarget.character import gltf_character  # noqa: E402
from tests.motion.retarget.heldout import (  # noqa: E402
    bpy_interpreter,
    build_heldout,
    heldout_glb,
    heldout_role_map,
)
from tests.motion.retarget.heldout import name_of as heldout_name_of  # noqa: E402
from tests.motion.retarget.mesh_feet import measure  # noqa: E402
from tests.motion.retarget.namings import (  # noqa: E402
    NAMINGS,
    ROLE_OF_UNREAL,
    bandai_rig,
    game_rig,
    name_in,
)

DATA = ROOT.parent / "shared" / "data"


def role_map_of(rest: Motion, naming: str, toes: bool) -> dict[str, str]:
    """``{role: joint}`` naming every role of ``rest`` (Unreal names) in ``naming``."""
    names = set(rest.skeleton.names)
    return {
        role: name_in(naming, u)
        for u, role in ROLE_OF_UNREAL.items()
        if u in names and (toes or not role.endswith("Toes"))
    }


@dataclass(frozen=True)
class Rig:
    """A test character: its rest pose in Unreal names, its GLB in each naming, the role map of
    its own names (with or without its toes) and where each Unreal joint is in a naming."""

    name: str
    rest: Motion
    glb: Callable[[str], bytes]
    role_map: Callable[[str, bool], dict[str, str]]
    name_of: Callable[[str, str], str]


def mannequin_rig(name: str, rest: Motion) -> Rig:
    """Segue's mannequin on ``rest`` (Unreal names)."""
    return Rig(
        name,
        rest,
        lambda naming: mannequin_glb(rest, names=[name_in(naming, n) for n in rest.skeleton.names]),
        lambda naming, toes: role_map_of(rest, naming, toes),
        name_in,
    )


def heldout_rig(python: Path, folder: Path) -> Rig:
    """The held-out character (``tests/motion/retarget/heldout.py``), built by Blender once."""
    own = build_heldout(python, folder)
    return Rig(
        "heldout",
        gltf_character(heldout_glb(own, "unreal")),
        lambda naming: heldout_glb(own, naming),
        lambda naming, toes: {r: j for r, j in heldout_role_map().items() if toes or not r.endswith("Toes")},
        heldout_name_of,
    )


def sources(folder: Path, full: bool) -> list[tuple[str, Path]]:
    """(name, BVH file) of each source; the demo's dance is made here."""
    out = [("walk", Path("sample:walk"))]
    demo = folder / "demo"
    subprocess.run(
        [sys.executable, "-m", "service.cli", "demo", "rhythm", "--out", str(demo)],
        cwd=ROOT, check=True, capture_output=True, text=True,
    )  # fmt: skip
    out.append(("rhythm-dance", demo / "rhythm" / "dance.bvh"))
    if full and (DATA / "bandai-namco").is_dir():
        out.append(("bandai-dance", DATA / "bandai-namco/dataset-1/dataset-1_dance-short_normal_001.bvh"))
        out.append(("cmu-salsa-60_02", DATA / "cmu-salsa/60_02_scaled.bvh"))
    return out


def _load_source(path: Path) -> Motion:
    m = load_motion(str(path))
    if str(path).startswith("sample:"):
        m, _ = without_reference_lead(m)  # as segue retarget does for a bundled sample
    return m


def _retarget(
    code: Path, src: Path, char: Path, out: Path, role_map: dict[str, str] | None
) -> tuple[bool, str]:
    cmd = [sys.executable, "-m", "service.cli", "retarget", str(src), "--to", str(char), "--out", str(out),
           "--events", "contacts", "--quiet"]  # fmt: skip
    if role_map is not None:
        map_file = out.with_suffix(".map.json")
        map_file.write_text(json.dumps(role_map))
        cmd += ["--map", str(map_file)]
    env = {**os.environ, "PYTHONPATH": str(code)}
    res = subprocess.run(cmd, cwd=code, env=env, capture_output=True, text=True, check=False)
    return res.returncode == 0, (res.stderr or res.stdout).strip()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--code", type=Path, default=ROOT, help="the checkout whose segue retargets")
    ap.add_argument("--keep", type=Path, help="keep the characters and outputs in this folder")
    ap.add_argument("--quick", action="store_true", help="the bundled sources only, no Bandai rig")
    args = ap.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="feet-mesh-"))
    folder.mkdir(parents=True, exist_ok=True)
    code = args.code.resolve()
    rigs = [mannequin_rig("game-rig", game_rig())]
    if not args.quick and (DATA / "bandai-namco").is_dir():
        rigs.append(mannequin_rig("bandai-rig", bandai_rig()))
    python = bpy_interpreter()
    if python is not None:
        rigs.append(heldout_rig(python, folder))
    else:
        print("no Blender (SEGUE_BPY_PYTHON): no held-out character rows", file=sys.stderr)
    rows = []
    for src_name, src_path in sources(folder, not args.quick):
        source = _load_source(src_path)
        for rig in rigs:
            rig_name, rest = rig.name, rig.rest
            for naming in NAMINGS:
                char = folder / f"{rig_name}-{naming}.glb"
                char.write_bytes(rig.glb(naming))
                out = folder / f"{src_name}-on-{rig_name}-{naming}.glb"
                role_map = rig.role_map(naming, True) if naming == "own" else None
                t0 = time.perf_counter()
                ok, message = _retarget(code, src_path, char, out, role_map)
                map_toes = role_map is not None
                if not ok and role_map is not None:  # a map cannot name toes the source lacks there
                    role_map = rig.role_map(naming, False)
                    ok, message = _retarget(code, src_path, char, out, role_map)
                    map_toes = False
                row: dict[str, Any] = {"source": src_name, "rig": rig_name, "naming": naming}
                if naming == "own":
                    row["map_toes"] = map_toes
                if not ok:
                    rows.append({**row, "error": message.splitlines()[-1] if message else "failed"})
                    continue
                row["retarget_s"] = round(time.perf_counter() - t0, 2)
                row.update(measure(out.read_bytes(), source, rest, naming, rig.name_of))
                rows.append(row)
                print(json.dumps(row), file=sys.stderr)
    worst: dict[str, dict[str, Any]] = {}
    for src_name in dict.fromkeys(r["source"] for r in rows):
        mine = [r for r in rows if r["source"] == src_name and "error" not in r]
        if not mine:
            continue
        worst[src_name] = {
            "sink_cm": max(r["sink_cm"] for r in mine),
            "lift_cm": max((r["lift_cm"] or 0.0) for r in mine),
            "foot_speed_ratio": max(r["foot_speed_ratio"] for r in mine),
            "contacts": sorted({r["contacts"] for r in mine}),
            "source_plants": mine[0]["source_plants"],
        }
    print(json.dumps({"code": str(code), "rows": rows, "worst": worst}, indent=1))


if __name__ == "__main__":
    main()
