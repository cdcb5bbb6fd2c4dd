"""Every kind of GLB export passes the Khronos glTF-Validator with 0 errors (and 0 warnings).

The validator is the npm package ``gltf-validator`` run by node (``tests/tools/gltf_validate.js``).
``tests/run.sh`` installs it (pinned, once) into ``$SEGUE_GLTF_VALIDATOR_DIR`` (default
``~/.cache/segue/gltf-validator``, outside the repository). Without node or the package these tests
skip with a message locally, and fail in CI (``CI=true``), where they are required.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import motion
from motion.export.bind import bound_glb
from motion.export.characters import combine_characters
from motion.export.events import contact_events
from motion.export.glb import glb_bytes, write_glb
from motion.export.mannequin import mannequin_glb
from motion.io import save_motion
from motion.resample import resample
from motion.retarget import retarget
from motion.retarget.character import gltf_character
from motion.samples import sample_path

from .retarget.gltf_rig import unreal_character_glb
from .synthetic import walking_biped
from .test_glb_game import lying_down

VALIDATOR_VERSION = "2.0.0-dev.3.10"  # keep in step with tests/run.sh
SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "gltf_validate.js"


def validator_dir() -> Path:
    default = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "segue" / "gltf-validator"
    return Path(os.environ.get("SEGUE_GLTF_VALIDATOR_DIR") or default)


def _walk() -> motion.Motion:
    return motion.read_bvh(sample_path("walk")).slice(1, 90)


def _crowd(n: int) -> motion.Motion:
    base = motion.read_bvh(sample_path("walk-05-01")).slice(0, 40)
    step = np.array([80.0, 0.0, 0.0])
    people = [replace(base, root_positions=base.root_positions + k * step) for k in range(n)]
    return combine_characters(people, [f"c{k}_" for k in range(n)])


def _write(kind: str, path: Path) -> None:
    """Write the GLB export of one kind to ``path``."""
    if kind.startswith("target-"):
        save_motion(_walk(), path, target=kind.removeprefix("target-"))
    elif kind == "single":
        save_motion(_walk(), path)
    elif kind == "in-place":
        save_motion(_walk(), path, in_place=True)
    elif kind == "fps-24":
        save_motion(resample(_walk(), 24.0), path)
    elif kind == "events":
        m = _walk()
        beats = [{"type": "beat", "index": 0, "time_s": 0.5}]
        save_motion(m, path, events=["contacts"], extra_events=beats)
        assert contact_events(m)
    elif kind == "crowd":
        save_motion(_crowd(5), path, events=["contacts"])
    elif kind == "crowd-in-place":
        save_motion(_crowd(3), path, in_place=True)
    elif kind == "other-skeleton":
        save_motion(motion.read_bvh(sample_path("start-walk-stop")).slice(0, 60), path)
    elif kind == "lying-rest-pose":
        save_motion(lying_down(walking_biped(frames=30)), path)
    elif kind == "single-frame":
        save_motion(_walk().slice(0, 1), path)
    elif kind.startswith("bound"):
        hero = unreal_character_glb()
        mode = "hips" if kind == "bound-hips" else "root"
        moved = retarget(_walk(), gltf_character(hero), root_motion=mode)
        evs = contact_events(moved)
        path.write_bytes(bound_glb(hero, moved, animation_only=kind == "bound-animation-only", events=evs))
    elif kind == "mannequin":
        path.write_bytes(mannequin_glb(motion.read_bvh(sample_path("walk-10-04"))))
    elif kind == "body":
        path.write_bytes(glb_bytes(_walk(), mesh="body"))
    elif kind == "crowd-body":
        path.write_bytes(glb_bytes(_crowd(3), mesh="body"))
    elif kind == "bvh-character":
        character = motion.read_bvh(sample_path("walk-10-04")).slice(0, 1)
        write_glb(retarget(_walk(), character, root_motion="hips"), path, ground_root=False)
    else:  # pragma: no cover - the list below names every kind
        raise AssertionError(kind)


KINDS = [
    "single",
    "in-place",
    "fps-24",
    "events",
    "crowd",
    "crowd-in-place",
    "other-skeleton",
    "lying-rest-pose",
    "single-frame",
    "target-gltf",
    "target-godot",
    "target-unity",
    "target-unreal",
    "bound",
    "bound-hips",
    "bound-animation-only",
    "bvh-character",
    "mannequin",
    "body",
    "crowd-body",
]


@pytest.fixture(scope="module")
def reports(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, Any]]:
    """The validator's report of every kind's GLB (one node process for all)."""
    node = shutil.which("node") or shutil.which("nodejs")
    package = validator_dir() / "node_modules" / "gltf-validator"
    missing = (
        "node is not installed"
        if node is None
        else f"gltf-validator is not installed in {package.parent} (bash tests/run.sh installs it)"
        if not package.is_dir()
        else None
    )
    if missing is None:
        version = json.loads((package / "package.json").read_text())["version"]
        if version != VALIDATOR_VERSION:
            missing = f"gltf-validator {version} is installed, not the pinned {VALIDATOR_VERSION}"
    if missing is not None:
        if os.environ.get("CI") == "true":
            pytest.fail(f"the glTF-Validator is required in CI: {missing}")
        pytest.skip(f"glTF-Validator tests skipped: {missing}")
    folder = tmp_path_factory.mktemp("glb")
    paths = {kind: folder / f"{kind}.glb" for kind in KINDS}
    for kind, path in paths.items():
        _write(kind, path)
    env = dict(os.environ, NODE_PATH=str(package.parent))
    out = subprocess.run(
        [str(node), str(SCRIPT), *map(str, paths.values())],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )
    assert out.returncode == 0, out.stderr
    by_file = {r["file"]: r for r in map(json.loads, out.stdout.splitlines())}
    return {kind: by_file[str(path)] for kind, path in paths.items()}


@pytest.mark.parametrize("kind", KINDS)
def test_glb_passes_the_khronos_validator(reports: dict[str, dict[str, Any]], kind: str) -> None:
    report = reports[kind]
    problems = [m for m in report["messages"] if m["severity"] <= 1]  # 0 errors, 1 warnings
    assert report["errors"] == 0 and report["warnings"] == 0, problems


def test_validator_catches_a_broken_file(tmp_path: Path, reports: dict[str, dict[str, Any]]) -> None:
    """The harness is live: a GLB whose skin points past the node list is an error."""
    del reports  # only for the skip/fail decision above
    src = tmp_path / "ok.glb"
    save_motion(walking_biped(frames=5), src)
    raw = src.read_bytes()
    n = int.from_bytes(raw[12:16], "little")
    doc = json.loads(raw[20 : 20 + n])
    doc["skins"][0]["joints"][0] = len(doc["nodes"]) + 5
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = raw[20 + n :]
    out = bytearray(raw[:12]) + len(text).to_bytes(4, "little") + raw[16:20] + text + rest
    out[8:12] = len(out).to_bytes(4, "little")
    bad = tmp_path / "bad.glb"
    bad.write_bytes(bytes(out))
    node = shutil.which("node") or shutil.which("nodejs")
    assert node is not None
    env = dict(os.environ, NODE_PATH=str(validator_dir() / "node_modules"))
    res = subprocess.run([node, str(SCRIPT), str(bad)], capture_output=True, text=True, env=env, check=True)
    assert json.loads(res.stdout)["errors"] >= 1
