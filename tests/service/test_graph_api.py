"""``GET /v1/databases/{id}/graph`` and ``POST /v1/databases/{id}/graph-edits`` end to end: a rhythm
database of the bundled CMU salsa leaders built through the API, its graph, edits that derive a new
database, jobs on it that obey the edits, the rules' 422s, and the original left as it was."""

from __future__ import annotations

from itertools import pairwise
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from engines.rhythm.choreography import GraphEditError, apply_edits
from schemas.movement_graph import MovementGraph, ResolvedEdit
from tests.engines.rhythm_salsa import SPEC

from .conftest import ready_database, wait_events
from .test_api import JSON, error_of

SEEDS = range(4)


@pytest.fixture(scope="module")
def salsa_db(client: TestClient) -> dict[str, Any]:
    return ready_database(client, SPEC)


def graph_of(client: TestClient, db_id: str) -> MovementGraph:
    r = client.get(f"/v1/databases/{db_id}/graph")
    assert r.status_code == 200, r.text
    return MovementGraph.model_validate(r.json())


def walks(client: TestClient, db_id: str) -> list[list[int]]:
    """The group sequence of each seed's dance, from the job reports (``annotations.movements``)."""
    out = []
    for seed in SEEDS:
        request = {
            "engine": "rhythm",
            "database": db_id,
            "music": {"bpm": 110, "duration_s": 24},
            "seed": seed,
        }
        job = client.post("/v1/jobs", json=request)
        assert job.status_code == 202, job.text
        events = wait_events(client, job.json()["id"])
        assert events[-1]["type"] == "done", events[-1]
        report = client.get(f"/v1/jobs/{job.json()['id']}/report").json()
        out.append([m["group"] for m in report["annotations"]["movements"]])
    return out


def pairs(ws: list[list[int]]) -> set[tuple[int, int]]:
    return {(a, b) for w in ws for a, b in pairwise(w)}


def test_graph_edits_derive_a_database_that_synthesis_obeys(
    client: TestClient, salsa_db: dict[str, Any]
) -> None:
    db_id = salsa_db["id"]
    g = graph_of(client, db_id)
    assert g.database == db_id and g.strongly_connected and g.kinematic_weight == 0.5
    assert {grp.representative.clip for grp in g.groups} <= set(salsa_db["clips"])
    before = walks(client, db_id)
    # cut the transitions the learned graph took (those the rules let go), add a missing one
    p = np.zeros((len(g.groups), len(g.groups)))
    for t in g.transitions:
        p[t.source, t.target] = t.probability
    counts: dict[tuple[int, int], int] = {}
    for w in before:
        for a, b in pairwise(w):
            counts[(a, b)] = counts.get((a, b), 0) + 1
    cut: list[dict[str, Any]] = []
    for (a, b), _ in sorted(counts.items(), key=lambda kv: -kv[1]):
        trial = [*cut, {"op": "cut", "source": a, "target": b}]
        try:
            apply_edits(p, [ResolvedEdit.model_validate(e) for e in trial])
        except GraphEditError:
            continue
        cut = trial
        if len(cut) == 3:
            break
    assert len(cut) == 3
    # the first cut given by an example clip span instead of a group id
    first = g.groups[cut[0]["source"]].representative
    by_span = [
        {**cut[0], "source": {"clip": first.clip, "seconds": [first.start_s + 0.1, first.end_s - 0.1]}},
        *cut[1:],
    ]
    a = max(range(len(g.groups)), key=lambda x: sum(w.count(x) for w in before))
    missing = [int(b) for b in np.flatnonzero(p[a] == 0) if b != a]
    body = {"edits": [*by_span, *({"op": "connect", "source": a, "target": b, "weight": 3} for b in missing)]}
    r = client.post(f"/v1/databases/{db_id}/graph-edits", json=body)
    assert r.status_code == 201, r.text
    derived = r.json()
    assert derived["status"] == "ready" and derived["kind"] == "rhythm" and derived["id"] != db_id
    assert derived["derived_from"]["parent"] == db_id
    resolved = derived["derived_from"]["edits"]
    assert [(e["op"], e["source"], e["target"]) for e in resolved[:3]] == [
        ("cut", c["source"], c["target"]) for c in cut
    ]
    # the same edits (by group id this time) name the same database: 200, same id
    same = [*cut, *({"op": "connect", "source": a, "target": b, "weight": 3.0} for b in missing)]
    again = client.post(f"/v1/databases/{db_id}/graph-edits", json={"edits": same})
    assert again.status_code == 200 and again.json()["id"] == derived["id"]
    # listed, with its summary and its provenance
    listed = {d["id"]: d for d in client.get("/v1/databases").json()}
    assert listed[derived["id"]]["derived_from"]["parent"] == db_id
    assert listed[derived["id"]]["summary"]["clips"] == salsa_db["summary"]["clips"]
    # its graph: the cuts gone, the additions there and marked, the rest as learned
    dg = graph_of(client, derived["id"])
    edges = {(t.source, t.target): t for t in dg.transitions}
    assert all((c["source"], c["target"]) not in edges for c in cut)
    assert all(not edges[(a, b)].learned for b in missing)
    assert dg.derived_from is not None and dg.derived_from.parent == db_id
    # the original is untouched
    assert graph_of(client, db_id) == g
    # synthesis on the derived database obeys every edit
    after = walks(client, derived["id"])
    assert not pairs(after) & {(c["source"], c["target"]) for c in cut}
    assert pairs(after) <= set(edges)
    assert any((a, b) in pairs(after) for b in missing)
    # it can be deleted; the parent stays
    assert client.delete(f"/v1/databases/{derived['id']}", headers=JSON).status_code == 204
    error_of(client.get(f"/v1/databases/{derived['id']}/graph"), 404, "not_found")
    assert client.get(f"/v1/databases/{db_id}").json()["status"] == "ready"


@pytest.mark.parametrize(
    ("edits", "problem", "message"),
    [
        ([{"op": "cut", "source": 400, "target": 0}], "unknown_group", "no group 400"),
        (
            [{"op": "cut", "source": {"clip": "salsa-leader-02", "frames": [9000, 9001]}, "target": 0}],
            "bad_span",
            "fall in none of its basic movements",
        ),
        (
            [{"op": "cut", "source": {"clip": "tango", "seconds": [1, 2]}, "target": 0}],
            "bad_span",
            "no clip 'tango'",
        ),
    ],
)
def test_edits_naming_no_group_answer_422(
    client: TestClient, salsa_db: dict[str, Any], edits: list[dict[str, Any]], problem: str, message: str
) -> None:
    err = error_of(client.post(f"/v1/databases/{salsa_db['id']}/graph-edits", json={"edits": edits}), 422)
    assert message in err["message"] and err["details"] == {"edit": 0, "problem": problem, "field": "source"}


def test_rule_breaking_edits_answer_422_naming_the_edit(client: TestClient, salsa_db: dict[str, Any]) -> None:
    db_id = salsa_db["id"]
    g = graph_of(client, db_id)
    k = len(g.groups)
    out: dict[int, list[int]] = {}
    into: dict[int, list[int]] = {}
    for t in g.transitions:
        out.setdefault(t.source, []).append(t.target)
        into.setdefault(t.target, []).append(t.source)
    a = 0
    dead = [{"op": "cut", "source": a, "target": b} for b in out[a]]
    err = error_of(client.post(f"/v1/databases/{db_id}/graph-edits", json={"edits": dead}), 422)
    assert err["details"]["problem"] == "dead_end"
    assert err["details"]["edit"] == len(dead) - 1 and f"edit {len(dead) - 1} (cut" in err["message"]
    target = max(into, key=lambda x: len(into[x]))
    cuts = [{"op": "cut", "source": s, "target": target} for s in into[target] if s != target]
    err = error_of(client.post(f"/v1/databases/{db_id}/graph-edits", json={"edits": cuts}), 422)
    assert err["details"]["problem"] == "unreachable" and target in err["details"]["unreachable_groups"]
    assert "unreachable from groups" in err["message"] and f"makes groups [{target}" in err["message"]
    b = next(x for x in range(k) if x not in out[1])
    err = error_of(
        client.post(
            f"/v1/databases/{db_id}/graph-edits",
            json={
                "edits": [
                    {"op": "weight", "source": 1, "target": out[1][0], "weight": 2},
                    {"op": "cut", "source": 1, "target": b},
                ]
            },
        ),
        422,
    )
    assert err["details"] == {"edit": 1, "problem": "no_transition"}
    for bad in (
        {"edits": [{"op": "weight", "source": 1, "target": out[1][0], "weight": 0}]},
        {"edits": [{"op": "weight", "source": 1, "target": out[1][0], "weight": -1}]},
        {"edits": [{"op": "weight", "source": 1, "target": out[1][0]}]},
        {"edits": []},
        {"edits": [{"op": "cut", "source": 1}]},
    ):
        error_of(client.post(f"/v1/databases/{db_id}/graph-edits", json=bad), 422, "invalid_request")
    inf = b'{"edits": [{"op": "weight", "source": 1, "target": 0, "weight": 1e999}]}'
    error_of(
        client.post(
            f"/v1/databases/{db_id}/graph-edits", content=inf, headers={"Content-Type": "application/json"}
        ),
        422,
    )
    assert graph_of(client, db_id) == g  # nothing changed


def test_graph_of_other_kinds_and_unknown_databases(client: TestClient, walk_db: dict[str, Any]) -> None:
    err = error_of(client.get(f"/v1/databases/{walk_db['id']}/graph"), 422, "invalid_request")
    assert "only 'rhythm' databases" in err["message"]
    edit = {"edits": [{"op": "cut", "source": 0, "target": 1}]}
    error_of(client.post(f"/v1/databases/{walk_db['id']}/graph-edits", json=edit), 422, "invalid_request")
    error_of(client.get("/v1/databases/nope/graph"), 404, "not_found")
    error_of(client.post("/v1/databases/nope/graph-edits", json=edit), 404, "not_found")
