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


def test_requests_and_specs_are_validated_with_the_registrys_models() -> None:
    """One table: each built-in engine's request is validated with the request model its registry
    line names, each kind's spec with its spec model, and the OpenAPI unions list the same models
    (built-in kinds in the order the document has always listed them)."""
    from typing import get_args

    from engines.registry import parse_database_spec, parse_job_request
    from schemas.jobs import RequestError

    built_in = registry._BUILT_IN
    for name, entry in built_in.items():
        assert engine_class(name).request_model is entry.request_model
        assert engine_class(name).spec_model is entry.spec_model
    requests = get_args(get_args(registry.request_union())[0])
    specs = get_args(get_args(registry.spec_union())[0])
    assert requests == tuple(b.request_model for b in built_in.values())
    assert specs == registry._spec_models()[: len(specs)]
    for kind in ("clips", "graph", "rhythm"):
        spec = parse_database_spec({"kind": kind, "clips": [{"bvh": "a.bvh"}]})
        assert type(spec) is registry.kind_class(kind).spec_model
    assert type(parse_job_request({"engine": "graph", "frames": 10})) is built_in["graph"].request_model
    with pytest.raises(RequestError, match="unknown engine 'nope'; available: annotations, clip, control"):
        parse_job_request({"engine": "nope"})
