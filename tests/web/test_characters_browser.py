"""Characters in the viewer (issue 38) in headless Chromium: a held-out skinned character uploaded as a
file shows the graph demo's result on its own mesh (pixels, not only the DOM), every tool's motion
on a character, and what an animator looks at (contacts, floor, goals, frame steps, camera).

Screenshots of each tool with a character go to tests/web/artifacts/<tool>-character.png (copied to
docs/screenshots/). Every wait is a hang guard, never a speed bar."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from motion import Motion, Skeleton
from motion import rotations as rot
from motion.io import load_motion
from motion.retarget.binding import Binding, apply_binding
from motion.retarget.character import gltf_character
from motion.samples import sample_path
from service.client import SegueClient
from service.demos import DEMOS
from tests.motion.retarget.gltf_rig import unreal_character_glb

from .conftest import screenshot
from .held_out_character import held_out_character_glb
from .test_browser import (
    BEST_DRAWN,
    drag,
    needs_engine,
    record_timing,
    reload_databases,
    select_database,
    state,
    wait,
)

pytestmark = pytest.mark.slow

HELD_OUT = "held-out-hero.glb"


def upload_character(page: Any, name: str = HELD_OUT) -> str:
    """Upload the held-out character with the page's "+ character" file input (POST /v1/files);
    the picker offers it and picks it. Returns its file id (the sha256 of its bytes)."""
    data = held_out_character_glb()
    file_id = hashlib.sha256(data).hexdigest()
    page.set_input_files(
        "#character-file", files=[{"name": name, "mimeType": "model/gltf-binary", "buffer": data}]
    )
    wait(
        page,
        f"s.characters.files.some((f) => f.id === '{file_id}') "
        f"&& document.querySelector('#character').value === '{file_id}'",
    )
    return file_id


def shown(page: Any, key: str, kind: str) -> dict[str, Any]:
    """Wait until viewer key ``key`` is drawn as a body of ``kind`` (file, clip or mannequin)."""
    wait(
        page,
        f"s.characters.shown['{key}'] && s.characters.shown['{key}'].kind === '{kind}' "
        f"&& !s.characters.loading['{key}']",
    )
    return dict(state(page, f".characters.shown['{key}']"))


def constraints_search(page: Any, segue: SegueClient) -> None:
    """The graph demo's database (`segue demo graph`), two body arrows, a 4-s search to its end."""
    db = segue.build_database(DEMOS["graph"].spec).id
    reload_databases(page)
    page.click("#tabs button[data-tool='constraints']")
    select_database(page, "cons-db", db)
    drag(page, "#cons-pad", [(0.5, 0.5), (0.5, 0.6)])
    drag(page, "#cons-pad", [(0.52, 0.9), (0.52, 0.95)])
    page.fill("#cons-length", "4")
    page.fill("#cons-budget", "1")
    page.click("#cons-go")
    wait(page, f"s.job && s.job.status === 'done' && {BEST_DRAWN}")


def test_a_held_out_character_shows_the_graph_demos_result_on_its_mesh(
    page: Any, segue: SegueClient, server: str
) -> None:
    """After the graph demo's search the result is on Segue's mannequin; the held-out character,
    uploaded as a file and chosen in the picker, then wears it: its own mesh and materials, lit,
    at least 3 times the lit pixels of the stick figure at the same moment, no JavaScript error."""
    needs_engine("graph")
    constraints_search(page, segue)
    current = state(page, ".current")
    mannequin = shown(page, "result", "mannequin")
    assert mannequin["mode"] == "animation" and mannequin["what"] == "result" and mannequin["vertices"] > 1000
    # the service's foot contacts (measured on the body) marked on the floor, and both goals drawn
    assert mannequin["contacts"] >= 2 and state(page, ".viewer.contacts.result") == mannequin["contacts"]
    wait(page, "s.goals && s.goals.length === 2")
    report = segue.report(state(page, ".job.id"), current["result"])
    goals = state(page, ".goals")
    assert [g["met"] for g in goals] == [
        report.constraint_errors[f"body[{i}]"]["satisfied"] for i in range(2)
    ]
    assert goals[1]["position"] == pytest.approx([0.2, 4], abs=0.05)
    page.locator("#scrub").fill("0.4")
    screenshot(page, "constraints-mannequin")

    file_id = upload_character(page)
    files = httpx.get(f"{server}/v1/files", timeout=30).json()
    assert any(f["id"] == file_id and f["name"] == HELD_OUT for f in files)  # uploaded as a file
    hero = shown(page, "result", "file")
    assert hero["character"] == file_id and hero["mode"] == "animation"
    assert hero["materials"] == ["skin", "suit"] and hero["bones"] == 22 and hero["meshes"] == 2
    assert state(page, ".current.result") == current["result"]
    page.uncheck("#trail")
    page.locator("#scrub").fill("0.4")
    lit = page.evaluate("window.__segue.litPixels()")
    record_timing(
        {"tool": "character-lit", **lit, "body_ms": round(hero["ms"]), "mannequin_ms": round(mannequin["ms"])}
    )
    assert lit["sticks"] > 100, lit  # the stick figure is drawn at all
    assert lit["bodies"] >= 3 * lit["sticks"], lit
    assert [e for e in page.errors if "pageerror" in e or "console" in e] == []
    assert state(page, ".errors") == []
    screenshot(page, "constraints-character")


def _binding(doc: dict[str, Any], source: Motion, character: Motion) -> Binding:
    """The binding as the page received it (JSON), for motion.retarget.binding.apply_binding."""
    s_index = {n: j for j, n in enumerate(source.skeleton.names)}
    t_index = {n: j for j, n in enumerate(character.skeleton.names)}
    hips = doc["hips"]
    return Binding(
        source=source.skeleton.names,
        target=character.skeleton.names,
        driven=np.array([t_index[j["joint"]] for j in doc["joints"]], dtype=np.intp),
        sources=np.array([s_index[j["source"]] for j in doc["joints"]], dtype=np.intp),
        offsets=np.array([j["offset"] for j in doc["joints"]]),
        rest_local=np.asarray(character.rotations[0]),
        hips=t_index[hips["joint"]],
        source_hips=s_index[hips["source"]],
        scale=hips["scale"],
        source_floor=hips["source_floor"],
        target_floor=hips["target_floor"],
    )


def test_a_clip_plays_on_the_character_as_the_service_binds_it(page: Any) -> None:
    """A clip in the library plays on the chosen character: the page applies the service's binding
    frame by frame exactly as motion.retarget.binding does in Python (joint positions within a
    millimetre), and the mannequin wears a clip nobody chose a character for."""
    page.set_input_files("#clip-file", str(sample_path("walk")))
    wait(page, "s.loaded.includes('07_01_walk_daz')")
    page.select_option("#character", "")
    assert shown(page, "clip", "mannequin")["mode"] == "binding"
    upload_character(page, "clip-hero.glb")
    info = shown(page, "clip", "file")
    assert info["what"] == "motion" and info["materials"] == ["skin", "suit"]
    doc = state(page, ".characters.bindings.clip")
    walk = load_motion("sample:walk")
    walk = walk.scaled(walk.metres_per_unit, "m")
    hero = gltf_character(held_out_character_glb())
    want = apply_binding(_binding(doc, walk, hero), walk, hero).global_positions()
    names = ["mixamorig:Hips", "mixamorig:LeftFoot", "mixamorig:RightHand", "mixamorig:Head"]
    for frame in (0, 100, 250):
        got = page.evaluate(f"window.__segue.characters.joints('clip', {frame / walk.fps}, {names})")
        for n in names:
            assert got[n] == pytest.approx(want[frame, hero.skeleton.names.index(n)].tolist(), abs=1e-3), (
                frame,
                n,
            )
    # the floor is at the character's soles: the lowest sole point while standing
    assert abs(state(page, ".viewer.floorY") - info["floor"]) < 1e-6 and -0.08 < info["floor"] < 0.08


def test_every_tool_on_a_character(page: Any, segue: SegueClient, tmp_path: Path) -> None:
    """Path (a result and a live walk), Partner (leader and follower), Timeline and Music (a live
    dance) on the held-out character, each saved as a screenshot; frame steps, speed and the
    camera that follows."""
    needs_engine("control")
    walk = segue.build_database(DEMOS["walk"].spec).id
    partner = segue.build_database(DEMOS["control"].spec).id
    segue.upload_clip(sample_path("salsa-leader-12"))
    reload_databases(page)
    # a character another client uploads (POST /v1/files) is offered without a reload
    rig = tmp_path / "api-rig.glb"
    rig.write_bytes(unreal_character_glb())
    api_rig = segue.upload_file(rig).id
    wait(page, f"s.characters.options.some((o) => o.value === '{api_rig}')")
    upload_character(page)

    # Path: a result on the character, the path's ends drawn as goals
    select_database(page, "path-db", walk)
    arc = [(5 * (1 - math.cos(0.048 * i)), 5 * math.sin(0.048 * i)) for i in range(17)]
    drag(page, "#path-pad", [(0.5 + x / 10, 0.5 + z / 10) for x, z in arc], step_ms=180)
    page.fill("#path-budget", "2")
    page.click("#path-go")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    info = shown(page, "result", "file")
    assert info["contacts"] >= 2
    wait(page, "s.goals && s.goals.length === 2")
    # frame steps (paused), speed, the camera that follows
    page.click("#step-fwd")
    f0 = state(page, ".viewer.frames.result")
    page.click("#step-fwd")
    page.click("#step-fwd")
    assert state(page, ".viewer.frames.result") == f0 + 2 and not state(page, ".viewer.playing")
    page.click("#step-back")
    assert state(page, ".viewer.frames.result") == f0 + 1
    page.select_option("#speed", "0.25")
    page.select_option("#follow", "follow")
    assert state(page, ".viewer.speed") == 0.25 and state(page, ".viewer.follow") == "follow"
    page.click("#play")
    wait(page, "s.viewer.time > 0.3")
    screenshot(page, "path-character")
    page.select_option("#speed", "1")
    page.select_option("#follow", "stay")

    # Path, live: the walker arrives on the character while the path is drawn
    page.check("#path-live")
    page.fill("#path-latency", "1")
    arc = [(5 * (1 - math.cos(0.04 * i)), 5 * math.sin(0.04 * i)) for i in range(21)]
    drag(
        page,
        "#path-pad",
        [(0.5 + x / 10, 0.5 + z / 10) for x, z in arc],
        step_ms=180,
        pressed=lambda: wait(page, "s.pathLive && s.pathLive.skeleton"),
    )
    wait(page, "s.pathLive && s.pathLive.end")
    live = shown(page, "result", "file")
    assert live["live"] and live["mode"] == "binding"
    wait(page, f"s.characters.shown.result.frames === {state(page, '.pathLive.frames')}")
    page.uncheck("#path-live")

    # Partner: the leader and the follower, both on the character
    page.click("#tabs button[data-tool='partner']")
    assert state(page, ".viewer.characters") == []  # the Path tool's walker went with its tool
    select_database(page, "partner-db", partner)
    page.select_option("#partner-clip", "60_12_salsa_leader_30fps")
    page.fill("#partner-budget", "2")
    page.click("#partner-go")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    shown(page, "result", "file")
    shown(page, "leader", "file")
    screenshot(page, "partner-character")

    # Timeline: the annotation demo's result
    needs_engine("annotations")
    tl = segue.build_database(DEMOS["annotations"].spec).id
    reload_databases(page)
    page.select_option("#character", state(page, ".characters.files")[0]["id"])
    page.click("#tabs button[data-tool='timeline']")
    select_database(page, "tl-db", tl)
    page.dispatch_event("#tl-db", "change")
    wait(page, "s.timeline.tracks.length === 3")
    page.fill("#tl-frames", "240")
    page.dispatch_event("#tl-frames", "input")
    drag(page, "#tl-canvas", [(0.2, 0.68), (0.99, 0.68)])
    page.fill("#tl-budget", "1.5")
    page.click("#tl-go")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    shown(page, "result", "file")
    screenshot(page, "timeline-character")

    # Music: a live dance on the character
    needs_engine("rhythm")
    rhythm = segue.build_database(DEMOS["rhythm"].spec).id
    reload_databases(page)
    page.select_option("#character", state(page, ".characters.files")[0]["id"])
    page.click("#tabs button[data-tool='music']")
    select_database(page, "music-db", rhythm)
    page.fill("#music-bpm", "150")
    page.fill("#music-seconds", "6")
    page.click("#music-go")
    wait(page, "s.music.frames > 0")
    shown(page, "result", "file")
    wait(page, "s.characters.shown.result.frames >= 240")
    screenshot(page, "music-character")
    wait(page, "!s.music.running && s.music.end")


def test_the_bodies_joints_follow_their_own_rotations() -> None:
    """The held-out character is what the tests say it is: an A-pose, Mixamo names, 1.85 m."""
    hero = gltf_character(held_out_character_glb())
    pos = hero.global_positions()[0]
    names = hero.skeleton.names
    assert names[0] == "mixamorig:Hips" and isinstance(hero.skeleton, Skeleton)
    hand = pos[names.index("mixamorig:LeftHand")] - pos[names.index("mixamorig:LeftArm")]
    assert math.degrees(math.atan2(-hand[1], hand[0])) == pytest.approx(40, abs=1)
    assert not np.allclose(hero.rotations[0], rot.IDENTITY)
