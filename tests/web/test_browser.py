"""End-to-end tests of the front end in headless Chromium against the real service on 127.0.0.1.

Each test drives the page as a user would (buttons, file inputs, mouse on the canvases) and asserts
on ``window.__segue`` (the page's state), not on pixels, nor on times; each tool saves one
screenshot under tests/web/artifacts/. Each first solution's timing (measured in the page, from the
click to the solution's frames in the viewer) is recorded in tests/web/artifacts/timings.jsonl (or
``$SEGUE_WEB_TIMINGS``); ``bench/browser.py`` runs these tests and holds the figures to the bars
(first solution drawn within 1 s of pressing the button on a warm database, the page's own parse +
draw within 0.4 s). Waits are guards against a hang (``GUARD_MS``), never speed bars.
"""

from __future__ import annotations

import gzip
import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from engines.registry import UnavailableError, engine_class
from motion.samples import sample_path
from service.client import SegueClient
from service.demos import DEMOS
from tests.motion.bvh_helpers import under_static_root

from .conftest import ARTIFACTS, screenshot

pytestmark = pytest.mark.slow  # tests/run.sh runs these with CI=true or SEGUE_SLOW=1

GUARD_MS = 120_000
"""How long a wait may take before the test calls it a hang (a loaded machine is slow, not broken)."""
TIMINGS = Path(os.environ.get("SEGUE_WEB_TIMINGS") or ARTIFACTS / "timings.jsonl")
"""Where the tests record the page's timings (one JSON object a line; bench/browser.py reads them)."""
WALK = "07_01_walk_daz"
LEADER = "60_01_salsa_leader"
LEADER12 = "60_12_salsa_leader_30fps"  # the leader no couple of the demo's database danced with


def needs_engine(name: str) -> None:
    """Skip (with the reason) while an engine has not landed in this installation."""
    try:
        engine_class(name)
    except UnavailableError as exc:
        pytest.skip(f"engine {name!r} is not available yet: {exc}")


def state(page: Any, expr: str = "") -> Any:
    """A JSON copy of ``window.__segue`` (or of ``window.__segue<expr>``)."""
    return page.evaluate(f"JSON.parse(JSON.stringify(window.__segue{expr}))")


BEST_DRAWN = (
    "s.current && s.solutions.length && "
    "s.current.result === s.solutions.reduce((a, b) => (b.score < a.score ? b : a)).result"
)
"""The best solution received is the one drawn (its download may still be on its way at ``done``)."""


def wait(page: Any, condition: str, timeout_ms: float = GUARD_MS) -> None:
    """Wait until a JavaScript condition on ``s`` (= window.__segue) holds (a condition that throws,
    e.g. on a job the page has not submitted yet, does not hold); fail as soon as the page records a
    new error, or on timeout, with the condition's own error and the errors the page recorded."""
    seen = page.evaluate("window.__segue.errors.length")
    # a condition that throws is not met yet (``s.job.status`` before the click's job exists)
    body = f"const s = window.__segue; try {{ return {condition}; }} catch (e) {{ return false; }}"
    check = f"(() => {{ {body} }})()"
    try:
        page.wait_for_function(f"{check} || window.__segue.errors.length > {seen}", timeout=timeout_ms)
    except Exception:
        why = page.evaluate(
            f"(() => {{ const s = window.__segue; try {{ {condition}; return ''; }}"
            " catch (e) { return String(e); } })()"
        )
        pytest.fail(
            f"timed out waiting for {condition} ({why or 'false'}); page errors: {state(page, '.errors')}"
        )
    if not page.evaluate(check):
        pytest.fail(f"error while waiting for {condition}: {state(page, '.errors')[seen:]}")


def upload_samples(page: Any, *files: str) -> None:
    """Upload bundled samples with the library's sample picker."""
    for file in files:
        before = len(state(page, ".loaded"))
        page.select_option("#sample-select", f"{file}.bvh.gz")
        page.click("#sample-upload")
        wait(page, f"s.loaded.length > {before} || s.loaded.includes('{file}')")


def select_database(page: Any, select_id: str, db_id: str) -> None:
    page.wait_for_selector(f"#{select_id} option[value='{db_id}']", state="attached", timeout=GUARD_MS)
    page.select_option(f"#{select_id}", db_id)


def reload_databases(page: Any) -> None:
    """Make the page list databases built through the API (it also polls every 5 s)."""
    page.reload()
    page.wait_for_function("window.__segue && window.__segue.ready", timeout=GUARD_MS)


def drag(
    page: Any,
    selector: str,
    points: list[tuple[float, float]],
    step_ms: float = 0,
    pressed: Callable[[], None] | None = None,
    held: Callable[[], None] | None = None,
) -> None:
    """Press the mouse at the first point of a canvas (fractions of its box), move through the
    others (waiting ``step_ms`` between moves), release at the last; ``pressed()`` runs once the
    button is down, ``held()`` before it is released."""
    box = page.locator(selector).bounding_box()

    def at(p: tuple[float, float]) -> tuple[float, float]:
        return box["x"] + p[0] * box["width"], box["y"] + p[1] * box["height"]

    page.mouse.move(*at(points[0]))
    page.mouse.down()
    if pressed is not None:
        pressed()
    for p in points[1:]:
        page.mouse.move(*at(p), steps=2)
        if step_ms:
            page.wait_for_timeout(step_ms)
    if held is not None:
        held()
    page.mouse.up()


def first_solution(page: Any, tool: str, warm: bool) -> dict[str, Any]:
    """The tool's first solution is drawn: check it and record its timing (ms from the button press
    to the solution drawn, to its event, and the engine's own elapsed time) in ``TIMINGS`` (the
    bars are bench/browser.py's). Returns the page state."""
    s = state(page)
    assert s["current"]["tool"] == tool and s["current"]["frames"] > 1
    assert s["solutions"], "no solution event received"
    assert "result" in s["viewer"]["characters"]
    first = s["solutions"][0]
    timing = {
        "tool": tool,
        "warm": warm,
        "drawn_ms": round(s["timings"][tool], 1),
        "event_ms": round(first["at_ms"], 1),
        "engine_elapsed_ms": first["elapsed_ms"],
        "frames": s["current"]["frames"],
        **{k: round(s["firstDraw"][tool][k], 1) for k in ("download_ms", "parse_ms", "draw_ms")},
    }
    record_timing(timing)
    return s


def record_timing(timing: dict[str, Any]) -> None:
    TIMINGS.parent.mkdir(parents=True, exist_ok=True)
    with TIMINGS.open("a") as f:
        f.write(json.dumps(timing) + "\n")


def press_again(page: Any, button: str, tool: str) -> None:
    """Press a tool's button again (the database now loaded in a worker): a first solution is drawn
    (its timing recorded as ``warm``); the job is then cancelled from the page."""
    page.click(button)
    wait(page, f"s.current && s.current.tool === '{tool}' && s.job && s.current.job === s.job.id")
    first_solution(page, tool, warm=True)
    page.evaluate("(b => { if (!b.disabled) b.click(); })(document.getElementById('cancel-job'))")
    wait(page, "['done', 'cancelled'].includes(s.job.status)")


# ------------------------------------------------------------------------------ viewer + library


def test_load_clip_and_play(page: Any) -> None:
    """Upload a BVH with the file input; it is listed, drawn and plays; pause, scrub and speed work;
    a broken file's error appears next to the upload control."""
    page.set_input_files("#clip-file", str(sample_path("walk")))
    wait(page, f"s.loaded.includes('{WALK}')")
    s = state(page)
    assert any(c["name"] == f"{WALK}.bvh.gz" for c in s["clips"])
    assert s["viewer"]["characters"] == ["clip"] and s["current"]["frames"] == 317
    assert abs(s["viewer"]["duration"] - 316 / 120) < 1e-3
    wait(page, "s.viewer.playing && s.viewer.time > 0.2")
    page.click("#play")  # pause
    wait(page, "!s.viewer.playing")
    paused = state(page, ".viewer.time")
    page.wait_for_timeout(200)
    assert state(page, ".viewer.time") == paused
    page.locator("#scrub").fill("0.5")
    s = state(page)
    assert abs(s["viewer"]["time"] - s["viewer"]["duration"] / 2) < 0.02
    assert s["viewer"]["frames"]["clip"] == round(s["viewer"]["time"] * 120)
    # the page's fast BVH reader (used for results) agrees with three.js's BVHLoader (used here)
    agree = page.evaluate(
        """async () => {
          const { parseBvh, parseBvhText, bvhText, skeletonJoints } = await import('./js/bvh.js');
          const bytes = await (await fetch('/samples/07_01_walk_daz.bvh.gz')).arrayBuffer();
          const a = await parseBvh(bytes, 'a', 'cmu');
          const b = parseBvhText(await bvhText(bytes), 'b', 0.0254 / 0.45);
          let err = 0;
          a.positions.forEach((v, i) => { err = Math.max(err, Math.abs(v - b.positions[i])); });
          const joints = [a.joints.length, b.joints.length];
          const sites = [a.sites.filter(Boolean).length, b.sites.filter(Boolean).length];
          const skeleton = [skeletonJoints(a).join(), skeletonJoints(b).join()];
          return { err, frames: [a.frames, b.frames], joints, sites, skeleton, fps: b.fps };
        }"""
    )
    assert agree["frames"] == [317, 317] and agree["joints"][0] == agree["joints"][1] == 57
    # 43 joints and 14 End Sites; without them, the skeleton the API lists (its clip's joints)
    assert agree["sites"] == [14, 14] and agree["skeleton"][0] == agree["skeleton"][1]
    walk = next(c for c in s["clips"] if c["name"] == f"{WALK}.bvh.gz")
    assert agree["skeleton"][0].split(",") == walk["joints"]
    assert agree["err"] < 1e-4 and agree["fps"] == pytest.approx(120)
    page.select_option("#speed", "2")
    page.click("#play")
    wait(page, "s.viewer.playing")
    assert state(page, ".viewer.roots") == {"clip": "hip"}
    screenshot(page, "viewer")

    # a rig whose joint 0 is a static ground node (as Bandai-Namco's): the ring and the trail
    # follow the hips, not the node at the origin
    static = under_static_root(gzip.decompress(sample_path("run-09-04").read_bytes()).decode())
    page.set_input_files(
        "#clip-file", files=[{"name": "static-root.bvh", "mimeType": "text/plain", "buffer": static.encode()}]
    )
    wait(page, "s.loaded.includes('static-root')")
    assert state(page, ".viewer.roots") == {"clip": "hip"}

    page.set_input_files(
        "#clip-file",
        files=[{"name": "broken.bvh", "mimeType": "text/plain", "buffer": b"HIERARCHY\nROOT x\n"}],
    )
    page.wait_for_selector("#err-upload:not(:empty)")
    assert "broken.bvh" in page.text_content("#err-upload")
    assert state(page, ".errors")[-1]["code"] == "invalid_bvh"

    # a build that fails shows the build job's error next to the Build button
    upload_samples(page, "131_01_start_walk_stop")
    page.select_option("#db-kind", "clips")
    for clip in (WALK, "131_01_start_walk_stop"):
        page.check(f"#db-clips input[value='{clip}']")
    page.click("#db-build")
    page.wait_for_selector("#err-build:not(:empty)", timeout=GUARD_MS)
    assert "joint hierarchy" in page.text_content("#err-build")
    assert state(page, ".builds")[-1]["status"] == "failed"


def test_constraints_build_and_alternatives(page: Any, segue: SegueClient) -> None:
    """Library: upload two samples, build a graph database with progress. Constraints, on the
    database `segue demo graph` builds (its spec posted to the API): place two body arrows with the
    mouse and a length, receive alternatives, pick one, download BVH and GLB; the quality badge says
    what the result's report says."""
    needs_engine("graph")
    upload_samples(page, WALK, LEADER)
    page.select_option("#db-kind", "graph")
    page.fill("#db-name", "walk+salsa graph")
    for clip in (WALK, LEADER):
        page.check(f"#db-clips input[value='{clip}']")
    page.click("#db-build")
    wait(page, "s.builds.length && s.builds[s.builds.length - 1].status === 'ready'")
    build = state(page, ".builds")[-1]
    db = next(d for d in state(page, ".databases") if d["id"] == build["database"])
    assert db["kind"] == "graph" and db["status"] == "ready" and sorted(db["clips"]) == sorted([WALK, LEADER])
    assert page.locator(f"#db-list li[data-db='{db['id']}'] .status-ready").count() == 1
    label = page.text_content(f"#db-list li[data-db='{db['id']}'] .grow")
    assert label == "walk+salsa graph · graph", label
    assert_kept_shown(page, segue, db["id"])

    demo = segue.build_database(DEMOS["graph"].spec).id  # the database `segue demo graph` builds
    jumps = [{"bvh": f"sample:{n}"} for n in ("salsa-leader", "jump-13-11", "jump-13-32")]
    sparse = segue.build_database({"kind": "graph", "clips": jumps}).id  # the jumps join no transition
    reload_databases(page)
    assert_kept_shown(page, segue, sparse, left_out=2)
    page.click("#tabs button[data-tool='constraints']")
    select_database(page, "cons-db", demo)
    option = page.eval_on_selector(f"#cons-db option[value='{demo}']", "o => o.textContent")
    assert option.startswith("walk +3 · graph"), option  # named by its clips: the CLI gave no name
    drag(page, "#cons-pad", [(0.5, 0.5), (0.5, 0.6)])  # at the origin, facing +Z
    drag(page, "#cons-pad", [(0.52, 0.9), (0.52, 0.95)])  # 0.2 m right, 4 m ahead, facing +Z
    drag(page, "#cons-pad", [(0.3, 0.3), (0.3, 0.2)])  # a third arrow, removed with a right click
    box = page.locator("#cons-pad").bounding_box()
    page.mouse.click(box["x"] + 0.31 * box["width"], box["y"] + 0.3 * box["height"], button="right")
    arrows = state(page, ".constraints")
    assert len(arrows) == 2
    assert arrows[0]["position"] == pytest.approx([0, 0], abs=0.05) and abs(arrows[0]["heading_deg"]) < 1
    assert arrows[1]["position"] == pytest.approx([0.2, 4], abs=0.05)
    assert abs(arrows[1]["heading_deg"]) < 1
    page.fill("#cons-length", "4")
    page.fill("#cons-alts", "3")
    page.fill("#cons-budget", "1")
    page.click("#cons-go")
    wait(page, "s.current && s.current.tool === 'constraints'")
    wait(page, f"s.job.status === 'done' && {BEST_DRAWN}")
    s = first_solution(page, "constraints", warm=False)
    assert s["current"]["frames"] == 120
    assert len({sol["result"] for sol in s["solutions"]}) >= 2
    best = min(s["solutions"], key=lambda sol: sol["score"])
    assert s["current"]["result"] == best["result"]
    assert all(not sol["alternative"] for sol in s["solutions"] if sol["result"] == best["result"])
    # the drawn motion ends as far from the last arrow as its report says
    report = segue.report(s["job"]["id"], best["result"])
    said = report.constraint_errors["body[1]"]
    drawn = float(np.linalg.norm(np.subtract(s["current"]["root"][-1], [0.2, 4]))) * 100
    assert said["position_cm"] == pytest.approx(drawn, abs=3.0)
    assert s["quality"] == {"result": best["result"], "ok": report.ok, "reasons": report.reasons}
    badge = page.text_content("#sol-quality")
    assert badge.startswith("ok") if report.ok else badge.startswith("not ok")
    screenshot(page, "constraints")

    other = next(sol["result"] for sol in s["solutions"] if sol["result"] != best["result"])
    page.select_option("#alternatives", other)
    wait(page, f"s.current.result === '{other}'")

    with page.expect_download() as dl:
        page.click("#dl-bvh")
    assert dl.value.suggested_filename.endswith(f"{other}.bvh")
    with page.expect_download() as dl:
        page.click("#dl-glb")
    assert dl.value.suggested_filename.endswith(".glb")
    bvh, glb = state(page, ".downloads")[-2:]
    assert bvh["format"] == "bvh" and bvh["frames"] == 120
    assert glb["format"] == "glb" and glb["animations"] == 1
    assert glb["duration_s"] == pytest.approx(119 / 30, abs=0.05)

    # the character picker: the same result retargeted onto an uploaded clip's skeleton
    chars = page.eval_on_selector_all("#character option", "os => os.map((o) => o.value)")
    assert chars[0] == "" and len(chars) >= 2
    page.select_option("#character", chars[1])
    with page.expect_download() as dl:
        page.click("#dl-bvh")
    on_char = state(page, ".downloads")[-1]
    assert on_char["character"] == chars[1] and on_char["frames"] == 120
    text = Path(dl.value.path()).read_text()
    clip = next(c for c in segue.clips() if c.id == chars[1])
    joints = [ln.split()[1] for ln in text.splitlines() if ln.strip().startswith(("ROOT", "JOINT"))]
    assert joints == clip.joints
    page.select_option("#character", "")

    press_again(page, "#cons-go", "constraints")

    # the event stream drops mid-job: the page reconnects with after=<last id> and misses nothing
    page.fill("#cons-budget", "1.5")
    page.click("#cons-go")
    wait(page, "s.job && s.job.events.length >= 2 && s.job.status === 'running'")
    assert page.evaluate("window.__segue.dropEvents()")
    wait(page, f"s.job.status === 'done' && {BEST_DRAWN}")
    job = state(page, ".job")
    assert job["reconnects"] >= 1
    assert job["events"] == list(range(1, len(job["events"]) + 1))  # every event once, in order

    # an API error appears next to the control that caused it
    page.fill("#cons-length", "3500")  # 105,000 frames: over the schema limit
    page.click("#cons-go")
    page.wait_for_selector("#err-constraints:not(:empty)")
    assert "frames" in page.text_content("#err-constraints")
    assert state(page, ".errors")[-1]["where"] == "constraints"


# ------------------------------------------------------------------------------ engines as they land


def assert_kept_shown(page: Any, segue: SegueClient, db_id: str, left_out: int = 0) -> None:
    """The database list shows what a graph build kept as the API's summary says it: the figures in
    the entry's tooltip, every clip left out with its reason, and how many beside the frame count."""
    summary = segue.database(db_id).summary
    assert summary is not None and summary.graph is not None
    kept = summary.graph
    assert len(kept.dropped) == left_out
    entry = f"#db-list li[data-db='{db_id}']"
    title = page.get_attribute(f"{entry} .grow", "title")
    total = kept.kept_clips + left_out
    assert f"kept {kept.kept_clips} of {total} clips, {kept.kept_frames} of " in title, title
    assert all(f"{c.clip} ({c.frames} frames): {c.reason}" in title for c in kept.dropped), title
    figures = page.text_content(f"{entry} span.mono")
    assert figures.endswith(f" · {left_out} left out" if left_out else "f"), figures


def test_path_walk(page: Any, segue: SegueClient) -> None:
    """Perform a path with the mouse (sampled at 30 Hz) and receive a walk along it."""
    needs_engine("control")
    db = segue.build_database(DEMOS["walk"].spec).id  # the database `segue demo walk` builds
    reload_databases(page)
    select_database(page, "path-db", db)
    # an L-shaped path at about 1.2 m/s: 2.4 m ahead (+Z) then 1.2 m right, in about 3 s
    # a curve at about 1.3 m/s: 0.24 m every 180 ms along a circle of 5 m radius, turning 44 degrees
    # towards +X (the pad spans 10 m: fraction 0.5 is the origin)
    arc = [(5 * (1 - math.cos(0.048 * i)), 5 * math.sin(0.048 * i)) for i in range(17)]
    pts = [(0.5 + x / 10, 0.5 + z / 10) for x, z in arc]
    drag(page, "#path-pad", pts, step_ms=180)
    path = state(page, ".path")
    # sampled at exactly 30 Hz over the time the button was held, as the page timed it (no clock of
    # this process: its view of the page's timing includes the IPC in between)
    assert path["fps"] == 30 and len(path["points"]) == int(path["held_ms"] / 1000 * 30) + 1, path
    assert path["points"][0] == pytest.approx([0, 0], abs=0.05)
    assert path["points"][-1] == pytest.approx(list(arc[-1]), abs=0.1)  # the release point
    page.fill("#path-budget", "2")
    page.click("#path-go")
    wait(page, "s.current && s.current.tool === 'path'")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    s = first_solution(page, "path", warm=False)
    end = s["current"]["root"][-1]
    assert end == pytest.approx(path["points"][-1], abs=0.6)
    assert s["current"]["rootJoint"] == "hip" and s["viewer"]["roots"]["result"] == "hip"
    screenshot(page, "path")
    press_again(page, "#path-go", "path")


def test_path_live_walk(page: Any, segue: SegueClient) -> None:
    """Draw a path with "live while drawing": it streams to the live control session and the walker
    arrives while the button is still held, a fixed latency behind the pointer; at release the rest
    comes, one walker frame per path frame, ending near the release point."""
    needs_engine("control")
    db = segue.build_database(DEMOS["walk"].spec).id
    reload_databases(page)
    select_database(page, "path-db", db)
    page.check("#path-live")
    page.fill("#path-latency", "1")
    # 3.6 s along a gentle curve at about 1.3 m/s (as test_path_walk, longer); pressing the button
    # opens the session (on a busy server this takes a while: the drawing starts once it is open),
    # and the walker must arrive while the button is still held (live, not after the fact)
    arc = [(5 * (1 - math.cos(0.04 * i)), 5 * math.sin(0.04 * i)) for i in range(21)]
    drag(
        page,
        "#path-pad",
        [(0.5 + x / 10, 0.5 + z / 10) for x, z in arc],
        step_ms=180,
        pressed=lambda: wait(page, "s.pathLive && s.pathLive.skeleton"),
        held=lambda: wait(page, "s.pathLive.frames > 0"),
    )
    wait(page, "s.pathLive && s.pathLive.end")
    s = state(page)
    live = s["pathLive"]
    assert not live["errors"], live["errors"]
    skeleton = live["skeleton"]
    assert skeleton["control"] == "path" and skeleton["latency_frames"] == round(skeleton["fps"])  # 1 s
    # frames came while the button was held (the page's own count agrees)
    assert live["framesBeforeStop"] > 0, live
    # nothing came earlier than the stated latency allows
    assert live["maxAhead"] <= 0, live
    assert live["end"]["frames"] == live["frames"] == live["sent"] == s["current"]["frames"]
    current = s["current"]
    assert current["tool"] == "path" and current["live"]
    assert current["root"][-1] == pytest.approx(s["path"]["points"][-1], abs=0.6)  # near the release point
    screenshot(page, "path-live")


def test_partner_follower(page: Any, segue: SegueClient) -> None:
    """Pick a leader clip uploaded through the API (not from this page): the generated follower
    dances with the leader, both drawn. The database picker offers partner databases only."""
    needs_engine("control")
    db = segue.build_database(DEMOS["control"].spec).id  # the database `segue demo control` builds
    segue.upload_clip(sample_path("salsa-leader-12"))
    walk_spec = {"kind": "control", "pairs": [{"target": "sample:walk-10-04"}]}
    walks = segue.build_database(walk_spec | {"segmentation": {"method": "footplants"}}).id
    reload_databases(page)
    page.click("#tabs button[data-tool='partner']")
    offered = page.eval_on_selector_all("#partner-db option", "os => os.map(o => o.value)")
    assert db in offered and walks not in offered  # a walk database cannot dance with a leader
    assert walks in page.eval_on_selector_all("#path-db option", "os => os.map(o => o.value)")
    label = page.eval_on_selector(f"#partner-db option[value='{db}']", "o => o.textContent")
    assert label.startswith("salsa-follower +7 · control (partner)"), label
    select_database(page, "partner-db", db)
    assert LEADER12 not in state(page, ".loaded")  # uploaded by the API client, never parsed here
    page.select_option("#partner-clip", LEADER12)
    page.fill("#partner-budget", "2")
    page.click("#partner-go")
    wait(page, "s.current && s.current.tool === 'partner'")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    s = first_solution(page, "partner", warm=False)
    assert sorted(s["viewer"]["characters"]) == ["leader", "result"]
    assert page.text_content("#err-partner") == ""
    assert s["current"]["frames"] / s["current"]["fps"] == pytest.approx(422 / 30, abs=0.5)
    screenshot(page, "partner")
    press_again(page, "#partner-go", "partner")

    # another tool does not show this one's result
    page.click("#tabs button[data-tool='music']")
    s = state(page)
    assert s["current"] is None and s["viewer"]["characters"] == [] and s["solutions"] == []
    assert page.text_content("#sol-info") == "no result yet"


def test_partner_follower_spots(page: Any, segue: SegueClient) -> None:
    """Click where the follower starts and where she ends on the Partner pad (beside the leader's
    drawn path): the request carries them as ``bodies`` at the control's start and end, and the
    follower drawn back starts and ends on them."""
    needs_engine("control")
    db = segue.build_database(DEMOS["control"].spec).id
    clip = segue.upload_clip(sample_path("salsa-leader-12"))
    reload_databases(page)
    page.click("#tabs button[data-tool='partner']")
    select_database(page, "partner-db", db)
    page.select_option("#partner-clip", LEADER12)
    # drawn, with no skeleton error: the page's parse lists End Sites, the summary's skeleton not
    wait(page, f"s.partner.drawn === '{LEADER12}'")
    assert page.text_content("#err-partner") == ""
    wait(page, "document.querySelector('#partner-spots-info').textContent === 'no spots'")
    box = page.locator("#partner-pad").bounding_box()
    for fx, fy in ((0.3, 0.35), (0.7, 0.6)):
        page.mouse.click(box["x"] + fx * box["width"], box["y"] + fy * box["height"])
    spots = state(page, ".partner.spots")
    assert len(spots) == 2 and "end" in page.text_content("#partner-spots-info")
    page.fill("#partner-budget", "2")
    page.click("#partner-go")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    s = state(page)
    bodies = s["partner"]["bodies"]
    assert [b["time_s"] for b in bodies] == [0, pytest.approx((clip.frames - 1) / clip.fps, abs=1e-3)]
    root = s["current"]["root"]
    assert root[0] == pytest.approx(spots[0], abs=0.05) and root[-1] == pytest.approx(spots[1], abs=0.05)
    screenshot(page, "partner-spots")


def test_timeline_paint(page: Any, segue: SegueClient) -> None:
    """On an annotated database built through the API (no spec in this page), the label tracks come
    from its summary; paint do / don't labels on two tracks and receive a motion; correct a clip's
    labels (the server rebuilds with them)."""
    needs_engine("annotations")
    db = segue.build_database(DEMOS["annotations"].spec).id  # what `segue demo annotations` builds
    reload_databases(page)
    page.click("#tabs button[data-tool='timeline']")
    select_database(page, "tl-db", db)
    page.dispatch_event("#tl-db", "change")
    wait(page, "s.timeline.tracks.length === 3")
    assert [t["label"] for t in state(page, ".timeline.tracks")] == ["jump", "run", "walk"]  # its vocabulary
    page.fill("#tl-frames", "240")
    page.dispatch_event("#tl-frames", "input")
    # rows of 24 px in an 88-px canvas: walk (row 3) over the first 60 %, run (row 2) after it,
    # and never jump (row 1, painted with shift: don't)
    drag(page, "#tl-canvas", [(0.2, 0.68), (0.6, 0.68)])
    drag(page, "#tl-canvas", [(0.62, 0.41), (0.99, 0.41)])
    page.keyboard.down("Shift")
    drag(page, "#tl-canvas", [(0.2, 0.14), (0.99, 0.14)])
    page.keyboard.up("Shift")
    entries = page.evaluate("window.__segue.timeline.entries()")
    assert {(e["label"], e["value"]) for e in entries} == {("walk", 1), ("run", 1), ("jump", -1)}
    page.fill("#tl-budget", "1.5")
    page.click("#tl-go")
    wait(page, "s.current && s.current.tool === 'timeline'")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    s = first_solution(page, "timeline", warm=False)
    assert s["current"]["frames"] == 240
    screenshot(page, "timeline")
    press_again(page, "#tl-go", "timeline")

    # the correction loop over the API: the first 60 frames of an unlabelled walk do not run; the
    # server builds the corrected database, whose summary holds the correction
    page.click("#tool-timeline summary")
    clips = page.eval_on_selector_all("#corr-clip option", "os => os.map(o => o.value)")
    assert clips == [c["bvh"].removeprefix("sample:") for c in DEMOS["annotations"].spec["clips"]]
    page.select_option("#corr-clip", "walk-10-04")
    page.fill("#corr-label", "run")
    page.fill("#corr-start", "0")
    page.fill("#corr-end", "60")
    page.select_option("#corr-value", "-1")
    builds = len(state(page, ".builds"))
    page.click("#corr-go")
    wait(page, f"s.builds.length > {builds} && s.builds[s.builds.length - 1].status === 'ready'")
    corrected = state(page, ".builds")[-1]["database"]
    assert corrected != db and page.input_value("#tl-db") == corrected
    walk_labels = segue.database(corrected).summary.clips[5].labels
    assert {"label": "run", "start": 0, "end": 60, "value": -1} in [lb.model_dump() for lb in walk_labels]


@pytest.fixture
def rhythm_db(segue: SegueClient) -> str:
    needs_engine("rhythm")
    return segue.build_database(DEMOS["rhythm"].spec).id  # the database `segue demo rhythm` builds


def _steer(page: Any, x: float, y: float) -> None:
    """Point the music pad at ``(x, y)`` of its box in one move: a move in steps passes through
    headings in between, which a beat may record while this process is slow to send the rest."""
    box = page.locator("#music-pad").bounding_box()
    page.mouse.move(box["x"] + box["width"] * x, box["y"] + box["height"] * y, steps=1)


def test_music_live_session(page: Any, rhythm_db: str) -> None:
    """Pick a BPM and steer with the mouse: the live session streams one beat of dance per beat,
    drawn as it comes, each flashing the beat."""
    reload_databases(page)
    page.click("#tabs button[data-tool='music']")
    select_database(page, "music-db", rhythm_db)
    page.fill("#music-bpm", "150")
    page.fill("#music-seconds", "3")
    _steer(page, 0.85, 0.5)  # towards +X
    page.click("#music-pad")
    page.click("#music-go")
    wait(page, "s.music.running")
    wait(page, "s.music.frames > 0")
    page.wait_for_timeout(1000)
    _steer(page, 0.5, 0.85)  # towards +Z
    page.wait_for_timeout(500)
    screenshot(page, "music")  # mid-session
    wait(page, "!s.music.running && s.music.end")
    s = state(page)
    m = s["music"]
    assert m["mode"] == "live" and m["skeleton"]["joints"] > 10
    assert m["end"]["frames"] == m["frames"] == s["current"]["frames"]
    # 150 BPM for 3 s: 7-8 beats; more when the stop reaches a busy server late (it catches up on
    # every beat due, never skips one), so the upper bound only says the 3 s were honoured
    assert 5 <= m["end"]["beats"] <= 25
    assert s["beats"] == m["end"]["beats"]  # one flash per streamed beat
    assert s["current"]["frames"] / s["current"]["fps"] == pytest.approx(m["end"]["beats"] * 0.4, rel=0.35)
    record_timing({"tool": "music-live", "live": True, "drawn_ms": round(s["timings"]["music"], 1)})


def test_music_midi_job_beats(page: Any, rhythm_db: str) -> None:
    """Upload a MIDI song, record the steering against the metronome, then synthesize: beats flash
    while recording and again on the song's beats during the result's playback."""
    from engines.rhythm.music import write_midi

    song = write_midi([(0, 150.0)], end_tick=10 * 480)  # 10 quarter notes at 150 BPM: 4 s
    reload_databases(page)
    page.click("#tabs button[data-tool='music']")
    select_database(page, "music-db", rhythm_db)
    page.set_input_files(
        "#music-midi", files=[{"name": "song.mid", "mimeType": "audio/midi", "buffer": song}]
    )
    page.fill("#music-bpm", "150")
    page.fill("#music-seconds", "4")
    page.click("#music-go")
    wait(page, "s.music.running")  # the metronome runs (the pad steers only then)
    _steer(page, 0.85, 0.5)  # towards +X
    headed = "s.music.directions.some((d) => Math.round(d.heading_deg) === 90)"
    wait(page, headed)  # keyed on a beat; then the other way
    _steer(page, 0.5, 0.85)
    wait(page, "s.current && s.current.tool === 'music'")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    s = first_solution(page, "music", warm=False)
    assert s["music"]["mode"] == "record" and s["beats"] >= 5  # the metronome: 150 BPM for 4 s
    headings = [round(d["heading_deg"]) for d in s["music"]["directions"]]
    assert 90 in headings and 0 in headings
    assert s["current"]["frames"] / s["current"]["fps"] == pytest.approx(4.0, abs=0.5)
    wait(page, "s.music.resultBeats >= 5")  # the song's beats, from the result's report
    wait(page, f"s.beats > {s['beats']}")  # flashing again with the dance's playback


def test_music_recording_plays_with_the_dance(page: Any, rhythm_db: str) -> None:
    """Pick a recording: it is uploaded, the server tracks its beats for the job, and the page
    plays the song (WebAudio) in sync with the result's playback."""
    from tests.engines.audio_synthetic import drifting_beats, drum_track, encode

    beats = drifting_beats(120.0, 120.0, 4.0)
    song = encode(drum_track(beats, 4.0, seed=6), "WAV")
    reload_databases(page)
    page.click("#tabs button[data-tool='music']")
    select_database(page, "music-db", rhythm_db)
    page.set_input_files(
        "#music-midi", files=[{"name": "drums.wav", "mimeType": "audio/wav", "buffer": song}]
    )
    page.fill("#music-seconds", "1")
    page.click("#music-go")
    wait(page, "s.current && s.current.tool === 'music'")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    s = first_solution(page, "music", warm=False)
    assert s["music"]["song"]["name"] == "drums.wav"
    assert s["music"]["song"]["duration_s"] == pytest.approx(4.0, abs=0.05)
    wait(page, "s.music.resultBeats >= 6")  # the recording's beats, tracked by the worker
    wait(page, "s.music.songPlaying && s.music.songStarts >= 1")
