"""The engine registry: built-in engines load on first use; a missing one is a clear error."""

from __future__ import annotations

import pytest

from engines import registry
from engines.registry import UnavailableError, engine_class, kind_class
from schemas.databases import ClipsDatabaseSpec
from schemas.jobs import ClipRequest


@pytest.mark.parametrize(
    ("engine", "kind"),
    [("graph", "graph"), ("control", "control"), ("annotations", "annotated"), ("rhythm", "rhythm")],
)
def test_built_in_engines_load_by_name_and_kind(engine: str, kind: str) -> None:
    cls = engine_class(engine)
    assert cls.name == engine and cls.kind == kind
    assert kind_class(kind) is cls


def test_an_engine_whose_module_is_missing_is_unavailable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(
        registry._BUILT_IN,
        "ghost",
        registry.BuiltIn("engines.ghost_engine", "GhostEngine", "haunted", ClipRequest, ClipsDatabaseSpec),
    )
    with pytest.raises(UnavailableError, match="engine 'ghost' is not available"):
        engine_class("ghost")
    with pytest.raises(UnavailableError, match="kind 'haunted' is not available"):
        kind_class("haunted")


def test_unknown_names_list_what_is_available() -> None:
    with pytest.raises(UnavailableError, match="available: .*clip"):
        engine_class("nope")


def test_the_registry_and_the_schemas_name_the_same_models() -> None:
    """The unions of the OpenAPI document come from the registry; the schemas' own parsers
    (``parse_job_request``, ``parse_database_spec``) must accept exactly the same models."""
    from typing import get_args

    from schemas.databases import DatabaseSpec
    from schemas.jobs import REQUEST_MODELS, JobRequest

    built_in = registry._BUILT_IN
    for name, entry in built_in.items():
        assert REQUEST_MODELS[name] is entry.request_model
        assert engine_class(name).request_model is entry.request_model
        assert engine_class(name).spec_model is entry.spec_model
    requests = get_args(get_args(registry.request_union())[0])
    specs = get_args(get_args(registry.spec_union())[0])
    assert requests == get_args(get_args(JobRequest)[0])
    assert specs == get_args(get_args(DatabaseSpec)[0])
