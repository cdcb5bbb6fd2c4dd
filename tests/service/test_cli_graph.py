"""``segue graph`` and ``segue graph-edit`` on a database directory of the bundled salsa leaders."""

from __future__ import annotations

import json
from itertools import pairwise
from pathlib import Path

import pytest

from schemas import DatabaseInfo
from schemas.movement_graph import MovementGraph
from service.cli import main
from tests.engines.rhythm_salsa import SPEC


@pytest.fixture(scope="module")
def db_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("graph-cli")
    (root / "db.json").write_text(json.dumps(SPEC), encoding="utf-8")
    assert main(["build", str(root / "db.json"), "--out", str(root / "db"), "-q"]) == 0
    return root


def graph(path: Path, capsys: pytest.CaptureFixture[str]) -> MovementGraph:
    assert main(["graph", str(path), "--json"]) == 0
    return MovementGraph.model_validate_json(capsys.readouterr().out)


def test_graph_and_graph_edit(db_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = db_dir / "db"
    g = graph(db, capsys)
    info = DatabaseInfo.model_validate_json((db / "info.json").read_bytes())
    assert g.database == info.id and g.derived_from is None
    assert main(["graph", str(db)]) == 0
    text = capsys.readouterr().out
    assert f"{len(g.groups)} groups, {len(g.transitions)} transitions" in text
    first = g.groups[0].representative
    assert (
        f"group   0: {g.groups[0].size:3d} movements, e.g. {first.clip} frames {first.start_frame}-" in text
    )
    # cut a transition into a group others reach too, by clip span; weight another
    t = next(
        t
        for t in g.transitions
        if t.source != t.target
        and sum(u.target == t.target and u.source != t.target for u in g.transitions) >= 2
    )
    src = g.groups[t.source].representative
    edits = [
        {
            "op": "cut",
            "source": {"clip": src.clip, "frames": [src.start_frame + 1, src.end_frame - 1]},
            "target": t.target,
        },
        {
            "op": "weight",
            "source": 0,
            "target": next(u.target for u in g.transitions if u.source == 0),
            "weight": 2.5,
        },
    ]
    (db_dir / "edits.json").write_text(json.dumps(edits), encoding="utf-8")
    assert main(["graph-edit", str(db), str(db_dir / "edits.json"), "--out", str(db_dir / "db2")]) == 0
    assert "derived database" in capsys.readouterr().out
    d = graph(db_dir / "db2", capsys)
    assert d.derived_from is not None and d.derived_from.parent == info.id
    assert (t.source, t.target) not in {(u.source, u.target) for u in d.transitions}
    assert graph(db, capsys) == g  # the original directory is untouched
    # the same edits (wrapped in an object this time) give the same id
    (db_dir / "edits2.json").write_text(json.dumps({"edits": edits}), encoding="utf-8")
    assert main(["graph-edit", str(db), str(db_dir / "edits2.json"), "--out", str(db_dir / "db3"), "-q"]) == 0
    assert graph(db_dir / "db3", capsys).database == d.database
    # segue synth uses the derived directory like any other
    (db_dir / "req.json").write_text(
        json.dumps({"engine": "rhythm", "music": {"bpm": 110, "duration_s": 20}, "seed": 2}), encoding="utf-8"
    )
    args = ["synth", str(db_dir / "req.json"), "--db", str(db_dir / "db2"), "--out", str(db_dir / "o.bvh")]
    assert main([*args, "--report", str(db_dir / "r.json"), "-q"]) == 0
    report = json.loads((db_dir / "r.json").read_text(encoding="utf-8"))
    groups = [m["group"] for m in report["annotations"]["movements"]]
    allowed = {(u.source, u.target) for u in d.transitions}
    assert all(pair in allowed for pair in pairwise(groups))


@pytest.mark.parametrize(
    ("edits", "message"),
    [
        ([{"op": "cut", "source": 0, "target": 999}], "edit 0 (cut): target: no group 999"),
        ([{"op": "cut", "source": {"clip": "x", "frames": [0, 1]}, "target": 0}], "no clip 'x'"),
        ([{"op": "weight", "source": 0, "target": 1, "weight": -1}], "invalid JSON"),
    ],
)
def test_graph_edit_errors(
    db_dir: Path, edits: list[dict[str, object]], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    (db_dir / "bad.json").write_text(json.dumps(edits), encoding="utf-8")
    assert (
        main(["graph-edit", str(db_dir / "db"), str(db_dir / "bad.json"), "--out", str(db_dir / "bad")]) == 2
    )
    assert message in capsys.readouterr().err
    assert not (db_dir / "bad").exists()


def test_graph_of_a_non_rhythm_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "db.json").write_text(
        json.dumps({"kind": "clips", "clips": [{"bvh": "sample:walk"}]}), encoding="utf-8"
    )
    assert main(["build", str(tmp_path / "db.json"), "--out", str(tmp_path / "db"), "-q"]) == 0
    assert main(["graph", str(tmp_path / "db")]) == 2
    assert "only 'rhythm' databases have a movement graph" in capsys.readouterr().err
    assert main(["graph", str(tmp_path / "nowhere")]) == 2
    assert "is not a database directory" in capsys.readouterr().err


def test_spans_use_the_clip_names_of_the_spec(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A clip named in the spec is that name in the graph and in clip spans; others keep their stem."""
    spec = {
        "kind": "rhythm",
        "clips": [
            {"bvh": "sample:salsa-leader-02", "name": "first dance"},
            {"bvh": "sample:salsa-leader-04"},
        ],
        "fps": 30,
        "beats_per_movement": 4,
    }
    (tmp_path / "db.json").write_text(json.dumps(spec), encoding="utf-8")
    assert main(["build", str(tmp_path / "db.json"), "--out", str(tmp_path / "db"), "-q"]) == 0
    g = graph(tmp_path / "db", capsys)
    assert {grp.representative.clip for grp in g.groups} == {"first dance", "salsa-leader-04"}
    named = next(grp for grp in g.groups if grp.representative.clip == "first dance")
    r = named.representative
    target = next(u.target for u in g.transitions if u.source == named.id)
    span = {"clip": "first dance", "frames": [r.start_frame, r.end_frame]}
    edits = [{"op": "weight", "source": span, "target": target, "weight": 2}]
    (tmp_path / "e.json").write_text(json.dumps(edits), encoding="utf-8")
    assert (
        main(
            ["graph-edit", str(tmp_path / "db"), str(tmp_path / "e.json"), "--out", str(tmp_path / "d"), "-q"]
        )
        == 0
    )
    d = graph(tmp_path / "d", capsys)
    assert d.derived_from is not None and d.derived_from.edits[0].source == named.id
    (tmp_path / "bad.json").write_text(
        json.dumps([{"op": "cut", "source": {"clip": "salsa-leader-02", "frames": [10, 10]}, "target": 0}]),
        encoding="utf-8",
    )
    assert (
        main(["graph-edit", str(tmp_path / "db"), str(tmp_path / "bad.json"), "--out", str(tmp_path / "x")])
        == 2
    )
    assert (
        "no clip 'salsa-leader-02' among the database's examples (first dance, salsa-leader-04)"
        in capsys.readouterr().err
    )


def test_graph_into_a_closed_pipe_ends_quietly(db_dir: Path) -> None:
    """``segue graph DB | head -4`` (docs/rhythm.md): no ``Broken pipe`` error once head has gone."""
    from tests.service.test_cli_help import _into_closed_pipe

    r = _into_closed_pipe("graph", str(db_dir / "db"))
    assert r.stderr == "" and r.returncode == 141


def test_serve_import_takes_a_derived_folder_too(db_dir: Path, tmp_path: Path) -> None:
    """``segue serve --import``: a folder ``segue graph-edit`` wrote is imported under its derived id
    (checked against its parent's spec and clips and its edits), like the folder it came from."""
    from workers.imports import import_database_dir
    from workers.movement_graphs import graph_of_dir
    from workers.store import Store

    t = graph_of_dir(db_dir / "db").transitions[0]
    edits = [{"op": "weight", "source": t.source, "target": t.target, "weight": 2.0}]
    (db_dir / "import-edits.json").write_text(json.dumps(edits), encoding="utf-8")
    args = ["graph-edit", str(db_dir / "db"), str(db_dir / "import-edits.json"), "--out", str(tmp_path / "d")]
    assert main([*args, "-q"]) == 0
    store = Store(tmp_path / "data")
    parent, _ = import_database_dir(store, db_dir / "db", ["local"])
    derived, new = import_database_dir(store, tmp_path / "d", ["local"])
    assert new and derived.id == json.loads((tmp_path / "d" / "info.json").read_text())["id"]
    assert derived.derived_from is not None and derived.derived_from.parent == parent.id
    assert store.database_spec(derived.id) == store.database_spec(parent.id)
