"""Movement graphs of databases and the databases derived by editing them: a parent's movement
transition graph edited by choreographic rules (:meth:`engines.base.Engine.edit_movement_graph`,
the rhythm engine's), stored as a database of its own.

A derived database is content-addressed like a built one: its id is the sha256 of the parent's
id, the edits in canonical form (groups resolved to ids, ``connect``'s weight explicit) and the
schema version, so posting the same edits again (by group id or by clip span) names the same
database. It holds the parent's spec (so summaries and clip names stay as they were), the parent's
arrays with the edited ``rhythm.p``, and a :class:`schemas.movement_graph.DerivedFrom` in its info
(parent and edits). The parent is untouched; deleting either leaves the other whole (the arrays
are a full copy: a database never depends on another being there).

Used by ``GET /v1/databases/{id}/graph``, ``POST /v1/databases/{id}/graph-edits`` (on the store)
and by ``segue graph`` / ``segue graph-edit`` (on database directories).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from engines.base import EngineError
from engines.registry import EngineClass, kind_class
from schemas import DatabaseInfo, DatabaseStatus
from schemas.common import SCHEMA_VERSION
from schemas.movement_graph import DerivedFrom, GraphEdits, MovementGraph, ResolvedEdit

from .store import NotFoundError, Store, load_npz, now, npz_bytes


def derived_database_id(parent: str, edits: list[ResolvedEdit]) -> str:
    """Content address of the database ``parent`` + ``edits`` (module doc)."""
    payload = json.dumps(
        {"schema": SCHEMA_VERSION, "parent": parent, "edits": [e.model_dump(mode="json") for e in edits]},
        sort_keys=True,
        separators=(",", ":"),
    )
    return hashlib.sha256(b"graph-edits\n" + payload.encode()).hexdigest()


def movement_graph_engine(info: DatabaseInfo) -> EngineClass:
    """The engine of ``info``'s kind; :class:`EngineError` unless its databases have a movement
    graph."""
    engine = kind_class(info.kind)
    engine.check_movement_graph(info.id)
    return engine


def graph_of(arrays: Any, info: DatabaseInfo, spec: dict[str, Any]) -> MovementGraph:
    """The movement graph of a ready database (its arrays, info and stored spec)."""
    return movement_graph_engine(info).movement_graph(arrays, info.id, spec, info.derived_from)


def derive(info: DatabaseInfo, arrays: Any, body: GraphEdits) -> tuple[DatabaseInfo, dict[str, Any]]:
    """The info and arrays of the database derived from ``info`` by ``body``'s edits. Raises
    :class:`engines.base.EngineError` (naming the edit) when a rule is broken."""
    resolved, out = movement_graph_engine(info).edit_movement_graph(arrays, body, info.id)
    derived = DatabaseInfo(
        id=derived_database_id(info.id, resolved),
        kind=info.kind,
        name=body.name or (f"{info.name} (edited)" if info.name else None),
        status=DatabaseStatus.ready,
        clips=list(info.clips),
        frames=info.frames,
        fps=info.fps,
        created_at=now(),
        derived_from=DerivedFrom(parent=info.id, edits=resolved),
    )
    return derived, out


def derive_in_store(store: Store, info: DatabaseInfo, body: GraphEdits) -> tuple[DatabaseInfo, bool]:
    """Derive from a ready database of the store; returns the derived database's info and whether
    it was created (False: the same edits of the same parent exist already, returned as they are)."""
    arrays = store.database_arrays(info.id)
    derived, out = derive(info, arrays, body)
    try:
        existing = store.database_info(derived.id)
        if existing.status == DatabaseStatus.ready:
            return existing, False
    except NotFoundError:
        pass
    store.put_database_arrays(derived.id, out)  # the data first: never a ready info without it
    store.put_database_info(derived, store.database_spec(info.id))
    return store.database_info(derived.id), True


def _read_dir(db_dir: Path) -> tuple[DatabaseInfo, dict[str, Any], dict[str, Any]]:
    try:
        info = DatabaseInfo.model_validate_json((db_dir / "info.json").read_bytes())
        spec = dict(json.loads((db_dir / "spec.json").read_bytes()))
        arrays = load_npz((db_dir / "data.npz").read_bytes())
    except OSError as exc:
        raise EngineError(f"{db_dir} is not a database directory ({exc.strerror or exc})") from None
    return info, spec, arrays


def graph_of_dir(db_dir: Path) -> MovementGraph:
    """The movement graph of a database directory (``segue build`` / ``segue graph-edit``)."""
    info, spec, arrays = _read_dir(db_dir)
    return graph_of(arrays, info, spec)


def derive_dir(db_dir: Path, body: GraphEdits, out_dir: Path) -> DatabaseInfo:
    """Write the database derived from directory ``db_dir`` by ``body`` into ``out_dir`` (created;
    files replaced): the parent's spec, the edited arrays and the info with ``derived_from``."""
    info, spec, arrays = _read_dir(db_dir)
    derived, out = derive(info, arrays, body)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "data.npz").write_bytes(npz_bytes(out))
    (out_dir / "spec.json").write_text(json.dumps(spec, indent=2), encoding="utf-8")
    (out_dir / "info.json").write_text(derived.model_dump_json(indent=2), encoding="utf-8")
    return derived
