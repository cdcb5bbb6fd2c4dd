"""The page never leaves a user guessing (issue 38), in headless Chromium: switching tools clears the
other tool's solutions and job state; a button that cannot act says why beside it; a build's
progress only moves forward, phase by phase; a finished job says so with its quality verdict.

Each of these failed on the page before issue 38: a Path job pressed just before switching tools
went on to show its solutions and `done · best r1` under Constraints and Music; Search without an
arrow submitted a search of nothing, and while the database was building it said "choose a ready
graph database first", as if there were none; the build went `50% 1816 frames`, then
`0% graph: features`."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import httpx
import pytest

from service.client import SegueClient
from service.demos import DEMOS
from tests.live_server import live_server

from .conftest import screenshot
from .test_browser import (
    BEST_DRAWN,
    GUARD_MS,
    drag,
    needs_engine,
    reload_databases,
    select_database,
    state,
    wait,
)
from .test_characters_browser import constraints_search

pytestmark = pytest.mark.slow


def _newest_synth_job(server: str) -> dict[str, Any]:
    jobs = [j for j in httpx.get(f"{server}/v1/jobs", timeout=30).json() if j["kind"] == "synth"]
    return dict(jobs[0])


def _wait_finished(segue: SegueClient, job_id: str) -> None:
    page_guard = GUARD_MS / 1000
    import time

    deadline = time.monotonic() + page_guard
    while segue.job(job_id).status.value not in ("done", "failed", "cancelled"):
        assert time.monotonic() < deadline, f"job {job_id} did not end"
        time.sleep(0.2)


def _clear(page: Any) -> dict[str, Any]:
    """What the solution bar shows: nothing of any job."""
    return {
        "info": page.text_content("#sol-info"),
        "solutions": page.eval_on_selector_all("#alternatives option", "os => os.map(o => o.textContent)"),
        "job_state": page.text_content("#job-state") if page.is_visible("#job-state") else "",
        "badge": page.is_visible("#sol-quality"),
        "characters": state(page, ".viewer.characters"),
        "downloads": page.is_enabled("#dl-glb"),
    }


NOTHING = {
    "info": "no result yet",
    "solutions": [],
    "job_state": "",
    "badge": False,
    "characters": [],
    "downloads": False,
}


def test_switching_tools_clears_the_other_tools_job(page: Any, segue: SegueClient, server: str) -> None:
    """A Path job pressed and left for Constraints: neither Constraints nor Music ever shows its
    solutions, its state or its drawing (it is cancelled); a finished one goes too."""
    needs_engine("control")
    db = segue.build_database(DEMOS["walk"].spec).id
    reload_databases(page)
    select_database(page, "path-db", db)
    arc = [(5 * (1 - math.cos(0.048 * i)), 5 * math.sin(0.048 * i)) for i in range(12)]
    drag(page, "#path-pad", [(0.5 + x / 10, 0.5 + z / 10) for x, z in arc], step_ms=120)
    page.fill("#path-budget", "3")
    page.click("#path-go")
    page.click("#tabs button[data-tool='constraints']")
    wait(page, "s.tool === 'constraints'")
    job = _newest_synth_job(server)
    _wait_finished(segue, job["id"])
    page.wait_for_timeout(1500)  # anything still on its way from the job has arrived
    assert _clear(page) == NOTHING
    page.click("#tabs button[data-tool='music']")
    assert _clear(page) == NOTHING
    # a finished Path job, its result drawn: another tool starts clear as well
    page.click("#tabs button[data-tool='path']")
    page.click("#path-go")
    wait(page, f"s.job && ['done', 'cancelled'].includes(s.job.status) && {BEST_DRAWN}")
    assert page.text_content("#job-state").startswith(("done · best", "cancelled · best"))
    page.click("#tabs button[data-tool='constraints']")
    assert _clear(page) == NOTHING
    page.click("#tabs button[data-tool='music']")
    assert _clear(page) == NOTHING
    screenshot(page, "switched-tools")


def test_a_finished_job_says_so_with_its_verdict(page: Any, segue: SegueClient) -> None:
    """Beside Cancel: `done · best rN · ok` (or `not ok`), as the result's report says."""
    needs_engine("graph")
    constraints_search(page, segue)
    s = state(page)
    report = segue.report(s["job"]["id"], s["job"]["end"]["result"])
    verdict = "ok" if report.ok else "not ok"
    assert re.match(
        rf"done · best {s['job']['end']['result']} · {verdict}( ·|$)", page.text_content("#job-state")
    )


def test_search_without_an_arrow_says_why(page: Any, segue: SegueClient, server: str) -> None:
    """Search with no arrow submits nothing and says what to do, beside the button; other tools'
    buttons that cannot act say why too."""
    needs_engine("graph")
    db = segue.build_database(DEMOS["graph"].spec).id
    reload_databases(page)
    page.click("#tabs button[data-tool='constraints']")
    select_database(page, "cons-db", db)
    page.click("#cons-clear")
    before = len(httpx.get(f"{server}/v1/jobs", timeout=30).json())
    page.click("#cons-go")
    page.wait_for_selector("#err-constraints:not(:empty)", timeout=GUARD_MS)
    assert "place at least one body arrow" in page.text_content("#err-constraints")
    assert state(page, ".errors")[-1]["code"] == "no_constraints" and state(page, ".job") is None
    assert len(httpx.get(f"{server}/v1/jobs", timeout=30).json()) == before  # nothing submitted
    # the Music tool's Stop with nothing playing, and a label track without a name
    page.click("#tabs button[data-tool='music']")
    page.click("#music-stop")
    page.wait_for_selector("#err-music:not(:empty)", timeout=GUARD_MS)
    assert "nothing is playing" in page.text_content("#err-music")
    page.click("#tabs button[data-tool='timeline']")
    page.fill("#tl-new", "")
    page.click("#tl-add")
    page.wait_for_selector("#err-timeline:not(:empty)", timeout=GUARD_MS)
    assert "name the label track" in page.text_content("#err-timeline")
    assert "no result" in page.get_attribute("#dl-glb", "title")


def test_a_build_moves_forward_and_search_says_it_waits(browser: Any, tmp_path: Path) -> None:
    """A first visit builds the graph demo's database: every progress the page shows moves forward
    and names its phase; Search meanwhile says the database is still building (with how far), and
    the message goes once it is ready."""
    needs_engine("graph")
    with live_server(tmp_path, workers=1) as url:
        context = browser.new_context(viewport={"width": 1400, "height": 820})
        context.set_default_timeout(GUARD_MS)
        page = context.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        try:
            page.goto(url + "/")
            page.wait_for_function("window.__segue && window.__segue.ready", timeout=GUARD_MS)
            page.click("#tabs button[data-tool='constraints']")
            drag(page, "#cons-pad", [(0.5, 0.5), (0.5, 0.6)])
            # every text the build status and the Constraints tool's error line show, as they change
            page.evaluate(
                """() => {
                  window.__shown = { status: [], error: [] };
                  for (const [id, list] of [['db-status', 'status'], ['err-constraints', 'error']]) {
                    const el = document.getElementById(id);
                    new MutationObserver(() => window.__shown[list].push(el.textContent))
                      .observe(el, { childList: true, characterData: true, subtree: true });
                  }
                }"""
            )
            page.click("#welcome-demos button[data-demo='graph']")
            page.click("#cons-go")
            page.wait_for_function("window.__shown.error.some((m) => m !== '')", timeout=GUARD_MS)
            page.wait_for_function("window.__segue.welcome.built.length === 1", timeout=GUARD_MS)
            page.wait_for_function(
                "document.querySelector('#err-constraints').textContent === ''", timeout=GUARD_MS
            )
            shown = page.evaluate("window.__shown.status")
            progress = [m for m in shown if re.match(r"^\d+% ", m)]
            assert len(progress) >= 3, shown
            percents = [int(m.split("%", 1)[0]) for m in progress]
            assert percents == sorted(percents), progress
            assert all(
                re.match(r"^\d+% [a-z][a-z ]*: ", m) or m.endswith("% built") for m in progress
            ), progress
            phases = {m.split("% ", 1)[1].split(":", 1)[0] for m in progress}
            assert {"motion library", "graph"} <= phases, progress
            message = next(m for m in page.evaluate("window.__shown.error") if m)
            assert "graph database" in message and "is still building" in message, message
            assert "[database_building]" in message, message
            assert state(page, ".builds")[-1]["status"] == "ready"
        finally:
            context.close()
    assert errors == []
