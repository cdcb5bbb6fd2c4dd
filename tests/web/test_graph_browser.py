"""The movement-graph view (web/js/graph.js) in headless Chromium: the graph of a rhythm database of
the bundled salsa leaders drawn as nodes with a pose and arrows; cut an arrow, connect two groups
with a shift-click, derive the database (selected in the Music tool), and a rule-breaking edit
shown as the server's 422."""

from __future__ import annotations

from typing import Any

import pytest

from service.client import SegueClient
from tests.engines.rhythm_salsa import SPEC

from .conftest import screenshot
from .test_browser import GUARD_MS, needs_engine, reload_databases, select_database, state, wait

pytestmark = pytest.mark.slow  # tests/run.sh runs these with CI=true or SEGUE_SLOW=1


def _safe_cut(transitions: list[dict[str, Any]]) -> tuple[int, int]:
    """A transition between two groups whose target other groups reach too (no rule breaks)."""
    into: dict[int, set[int]] = {}
    for t in transitions:
        if t["source"] != t["target"]:
            into.setdefault(t["target"], set()).add(t["source"])
    t = next(t for t in transitions if t["source"] != t["target"] and len(into[t["target"]]) >= 2)
    return t["source"], t["target"]


def test_graph_view_cut_connect_derive(page: Any, segue: SegueClient) -> None:
    needs_engine("rhythm")
    db = segue.build_database(SPEC).id
    reload_databases(page)
    page.click("#tabs button[data-tool='music']")
    select_database(page, "music-db", db)
    page.click("#graph-view summary")  # opening the view loads the selected database's graph
    wait(page, f"s.graph.database === '{db}'")
    server = segue.graph(db)
    assert page.locator("#graph-svg g.node").count() == len(server.groups)
    assert page.locator("#graph-svg path.edge").count() == len(server.transitions)
    assert page.locator("#graph-svg g.node path.figure").first.get_attribute("d").count("L") >= 10
    g = state(page, ".graph")
    a, b = _safe_cut(g["transitions"])
    page.dispatch_event(f"#graph-svg path.edge[data-source='{a}'][data-target='{b}']", "click")
    wait(page, f"s.graph.cuts.length === 1 && s.graph.cuts[0][0] === {a} && s.graph.cuts[0][1] === {b}")
    assert page.locator("#graph-svg path.edge.cut").count() == 1
    # a missing transition: click its source, shift-click its target
    edges = {(t["source"], t["target"]) for t in g["transitions"]}
    c, d = next(
        (x, y)
        for x in range(len(g["groups"]))
        for y in range(len(g["groups"]))
        if x != y and (x, y) not in edges
    )
    page.click(f"#graph-svg g.node[data-group='{c}']")
    page.click(f"#graph-svg g.node[data-group='{d}']", modifiers=["Shift"])
    wait(
        page,
        f"s.graph.connects.length === 1 && s.graph.connects[0][0] === {c} && s.graph.connects[0][1] === {d}",
    )
    assert page.locator("#graph-svg path.edge.pending").count() == 1
    # weight another existing transition with the pickers
    w_src, w_dst = next(
        (t["source"], t["target"])
        for t in g["transitions"]
        if (t["source"], t["target"]) not in ((a, b), (c, d))
    )
    page.select_option("#graph-from", str(w_src))
    page.select_option("#graph-to", str(w_dst))
    page.fill("#graph-weight", "4")
    page.click("#graph-weigh")
    wait(page, "s.graph.weights.length === 1 && s.graph.weights[0][2] === 4")
    assert page.locator("#graph-svg path.edge.weighted").count() == 1
    page.fill("#graph-weight", "1")
    page.locator("#graph-svg").scroll_into_view_if_needed()
    screenshot(page, "graph")
    page.click("#graph-submit")
    wait(page, "s.graph.derived && s.graph.database === s.graph.derived")
    derived = state(page, ".graph.derived")
    assert page.locator("#music-db").input_value() == derived  # the Music tool dances it now
    info = segue.database(derived)
    assert info.derived_from is not None and info.derived_from.parent == db
    assert [(e.op, e.source, e.target, e.weight) for e in info.derived_from.edits] == [
        ("cut", a, b, None),
        ("connect", c, d, 1.0),
        ("weight", w_src, w_dst, 4.0),
    ]
    new = {(t.source, t.target): t for t in segue.graph(derived).transitions}
    assert (a, b) not in new and not new[(c, d)].learned
    learned = {(t.source, t.target): t.probability for t in server.transitions}
    assert new[(w_src, w_dst)].probability > learned[(w_src, w_dst)]
    assert page.locator("#graph-svg path.edge.added").count() == 1  # drawn as added
    assert {(t.source, t.target) for t in segue.graph(db).transitions} == edges  # the original stays
    # cutting every transition out of a group: the server's 422 names the edit, nothing is derived
    out = [t["target"] for t in state(page, ".graph.transitions") if t["source"] == c]
    for target in out:
        page.dispatch_event(f"#graph-svg path.edge[data-source='{c}'][data-target='{target}']", "click")
    before = len(state(page, ".errors"))
    page.click("#graph-submit")
    page.wait_for_function(f"window.__segue.errors.length > {before}", timeout=GUARD_MS)
    err = state(page, ".errors")[-1]
    assert err["where"] == "graph" and err["status"] == 422
    assert "dead end" in page.locator("#err-graph").inner_text()
    assert state(page, ".graph.derived") == derived
