"""What the page says about its own state (issue 31): a job's finished state, the Music tool's
status once its result arrived, frames counted as the report counts them, errors that go once the
database they asked for exists, the Partner tool's leaders and spots, and a first visit's "try it".

Every wait is for a state with a generous timeout, never a wall-clock bar."""

from __future__ import annotations

import uuid
from pathlib import Path
from typing import Any

import pytest

from motion.samples import sample_path
from service.client import SegueClient
from service.demos import DEMOS
from tests.live_server import live_server

from .conftest import screenshot
from .test_browser import (
    BEST_DRAWN,
    GUARD_MS,
    LEADER12,
    needs_engine,
    reload_databases,
    select_database,
    state,
    wait,
)

pytestmark = pytest.mark.slow

HELD_OUT = (LEADER12, "sample:salsa-leader-12")
"""The demo's held-out leader: uploaded (by another test or this one) or still a bundled sample."""


def test_partner_offers_the_leaders_that_fit_and_the_followers_spots(page: Any, segue: SegueClient) -> None:
    """With the control demo's database the Partner tool offers leaders only (no walk, no follower,
    the same skeleton), the held-out leader first and by default; the job's end shows in words
    beside Cancel; after the result the pad offers the follower's start and end spots."""
    needs_engine("control")
    db = segue.build_database(DEMOS["control"].spec).id
    segue.upload_clip(sample_path("walk"))  # same skeleton, not dance material
    segue.upload_clip(sample_path("start-walk-stop"))  # another skeleton
    segue.upload_clip(sample_path("salsa-follower-02"))  # a follower of the database
    reload_databases(page)
    page.click("#tabs button[data-tool='partner']")
    select_database(page, "partner-db", db)
    page.dispatch_event("#partner-db", "change")
    wait(page, "s.partner.leaders.length > 0")
    leaders = state(page, ".partner.leaders")
    values = [leader["value"] for leader in leaders]
    assert not any("walk" in v or "follower" in v for v in values), values
    assert leaders[0]["heldOut"] and leaders[0]["value"] in HELD_OUT, leaders
    assert all(not leader["heldOut"] for leader in leaders[1:]), leaders  # the database's own leaders
    assert page.input_value("#partner-clip") in HELD_OUT
    # the default leader is drawn (a bundled sample is uploaded to be drawn and sent)
    wait(page, "document.querySelector('#partner-clip').value === '60_12_salsa_leader_30fps'")
    page.fill("#partner-budget", "5")
    page.click("#partner-go")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    s = state(page)
    assert s["partner"]["leader"] == LEADER12
    end = s["job"]["end"]
    assert "running…" in s["job"]["labels"] and s["job"]["labels"][-1] == s["job"]["label"]
    assert page.text_content("#job-state") == s["job"]["label"]
    assert s["job"]["label"].startswith(f"{end['type']} · best {end['result']}")
    assert "job-state done" in page.get_attribute("#job-state", "class") or end["type"] == "cancelled"
    assert s["quality"]["ok"], s["quality"]["reasons"]  # the held-out leader, not a walk
    # the result's start and end are offered on the pad; a click near the end moves it
    wait(page, "s.partner.offered")
    start, finish = state(page, ".partner.offered")
    root = s["current"]["root"]
    assert start == pytest.approx(root[0]) and finish == pytest.approx(root[-1])
    assert page.text_content("#partner-spots-info").startswith("follower starts")
    box = page.locator("#partner-pad").bounding_box()
    # 10 cm past the offered end, away from the start (the click moves the nearer spot)
    away = [finish[0] - start[0], finish[1] - start[1]]
    norm = max((away[0] ** 2 + away[1] ** 2) ** 0.5, 1e-9)
    target = [finish[0] + 0.1 * away[0] / norm, finish[1] + 0.1 * away[1] / norm]
    fx, fy = page.evaluate(f"window.__segue.partner.padFraction({target})")
    assert 0 < fx < 1 and 0 < fy < 1, (fx, fy)
    page.mouse.click(box["x"] + fx * box["width"], box["y"] + fy * box["height"])
    spots = state(page, ".partner.spots")
    assert spots[0] == pytest.approx(start) and spots[1] == pytest.approx(target, abs=0.03)
    assert page.text_content("#partner-spots-info").startswith("start ")
    screenshot(page, "partner-leaders")


def test_music_says_how_its_job_ended_in_the_reports_frames(page: Any, segue: SegueClient) -> None:
    """After a recorded Music job, its status line leaves "synthesizing…" for the result and how
    the job ended; the frames it and the solution bar name are the result's own (the rate its
    report's reasons count in), with the preview's rate beside them."""
    needs_engine("rhythm")
    db = segue.build_database(DEMOS["rhythm"].spec).id
    reload_databases(page)
    page.click("#tabs button[data-tool='music']")
    select_database(page, "music-db", db)
    page.select_option("#music-mode", "job")
    page.fill("#music-bpm", "150")
    page.fill("#music-seconds", "2")
    page.click("#music-go")
    wait(page, "s.current && s.current.tool === 'music' && !s.current.live")
    wait(page, f"['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    wait(page, "!s.music.info.includes('synthesizing') && !s.music.info.includes('searching')")
    s = state(page)
    current = s["current"]
    report = segue.report(s["job"]["id"], current["result"])
    assert (current["source_frames"], current["source_fps"]) == (report.frames, report.fps)
    frames = f"{report.frames} frames at {report.fps:g} fps"
    assert frames in page.text_content("#sol-info")
    info = page.text_content("#music-info")
    assert info == s["music"]["info"] and f"{s['job']['status']} · {current['result']} · {frames}" in info
    if abs(report.fps - current["fps"]) > 0.01:  # a preview at most 30 fps (a BVH's 30.0003)
        assert f"(drawn at {round(current['fps'])} fps)" in info


def test_a_database_error_goes_once_the_database_is_there(page: Any, segue: SegueClient) -> None:
    """ "Choose a ready database first" stays only until there is one: it goes when one is picked,
    and when the database is built (the page's list refresh)."""
    needs_engine("graph")
    page.click("#tabs button[data-tool='constraints']")
    page.evaluate("document.getElementById('cons-db').value = ''")  # as on a first visit: none
    page.click("#cons-go")
    wait(page, "s.errors.length && s.errors[s.errors.length - 1].code === 'no_database'")
    assert "choose a ready graph database" in page.text_content("#err-constraints")
    # a new database (a unique spec: a new content id), built through the API as the CLI user does
    spec = {"kind": "graph", "fps": 30, "clips": [{"bvh": "sample:walk-05-01"}], "name": uuid.uuid4().hex[:8]}
    spec["tau"] = 1.0 + int(uuid.uuid4().hex[:6], 16) * 1e-9
    segue.build_database(spec)
    page.wait_for_function("document.querySelector('#err-constraints').textContent === ''", timeout=GUARD_MS)
    # picking a database clears it too
    page.evaluate("document.getElementById('cons-db').value = ''")
    page.click("#cons-go")
    page.wait_for_selector("#err-constraints:not(:empty)", timeout=GUARD_MS)
    first = page.eval_on_selector_all("#cons-db option", "os => os.map(o => o.value)")[0]
    page.select_option("#cons-db", first)
    assert page.text_content("#err-constraints") == ""


def test_a_first_visit_offers_one_click_sample_databases(browser: Any, tmp_path: Path) -> None:
    """An empty server: the page offers the demos' databases; one click builds one from bundled
    samples and opens its tool on it; the offer goes once there is a database."""
    needs_engine("control")
    with live_server(tmp_path, workers=1) as url:
        context = browser.new_context(viewport={"width": 1400, "height": 820})
        context.set_default_timeout(GUARD_MS)  # a hang guard, not Playwright's 30-s default
        page = context.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        try:
            page.goto(url + "/")
            page.wait_for_function("window.__segue && window.__segue.ready", timeout=GUARD_MS)
            assert page.is_visible("#welcome")
            names = page.eval_on_selector_all("#welcome-demos button", "bs => bs.map(b => b.dataset.demo)")
            assert sorted(names) == sorted(DEMOS)
            screenshot(page, "welcome")
            page.click("#welcome-demos button[data-demo='walk']")
            wait(page, "s.welcome.built.length === 1")
            built = state(page, ".welcome.built")[0]
            assert built["tool"] == "path" and state(page, ".tool") == "path"
            assert page.input_value("#path-db") == built["database"]
            assert not page.is_visible("#welcome")
            assert state(page, ".builds")[-1]["status"] == "ready"
        finally:
            context.close()
    assert errors == []
