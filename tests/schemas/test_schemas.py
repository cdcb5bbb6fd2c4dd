"""The contract: specs, requests and their validation messages."""

from __future__ import annotations

import hashlib
import json

import pytest
from pydantic import ValidationError

from engines.registry import parse_database_spec, parse_job_request
from schemas.common import SCHEMA_VERSION
from schemas.databases import database_id
from schemas.jobs import RequestError


def test_database_spec_union_on_kind() -> None:
    spec = parse_database_spec({"kind": "rhythm", "clips": [{"bvh": "a.bvh"}], "beats_per_movement": 3})
    assert spec.kind == "rhythm" and spec.beats_per_movement == 3  # type: ignore[attr-defined]
    assert parse_database_spec('{"kind": "clips", "clips": [{"clip": "abc", "name": "x"}]}').kind == "clips"


@pytest.mark.parametrize(
    ("spec", "fragment"),
    [
        ({"kind": "nope", "clips": [{"bvh": "a.bvh"}]}, "does not match"),
        ({"kind": "clips", "clips": []}, "at least 1"),
        ({"kind": "clips", "clips": [{}]}, "exactly one of"),
        ({"kind": "clips", "clips": [{"bvh": "a", "clip": "b"}]}, "exactly one of"),
        ({"kind": "clips", "clips": [{"bvh": "a.bvh"}], "fps": -1}, "greater than or equal to 1"),
        ({"kind": "clips", "clips": [{"bvh": "a.bvh", "units": "furlong"}]}, "unknown units"),
        (
            {"kind": "clips", "clips": [{"bvh": "a.bvh", "labels": [{"label": "x", "start": 5, "end": 2}]}]},
            "end",
        ),
        ({"kind": "clips", "clips": [{"bvh": "a.bvh"}], "typo": 1}, "Extra inputs"),
    ],
)
def test_bad_specs_name_the_problem(spec: dict, fragment: str) -> None:
    with pytest.raises(ValidationError, match=fragment):
        parse_database_spec(spec)


def test_content_address_ignores_file_names_but_not_settings() -> None:
    a = parse_database_spec({"kind": "clips", "clips": [{"bvh": "x/a.bvh", "name": "a"}], "fps": 30})
    b = parse_database_spec({"kind": "clips", "clips": [{"bvh": "elsewhere/a.bvh", "name": "a"}], "fps": 30})
    c = parse_database_spec({"kind": "clips", "clips": [{"bvh": "x/a.bvh", "name": "a"}], "fps": 60})
    assert database_id(a, ["h1"]) == database_id(b, ["h1"])
    assert database_id(a, ["h1"]) != database_id(a, ["h2"])
    assert database_id(a, ["h1"]) != database_id(c, ["h1"])
    # a clip named by default is named as reports name it: what the CLI builds from a spec file (no
    # names) has the id the API computes (names filled in)
    d = parse_database_spec({"kind": "clips", "clips": [{"bvh": "elsewhere/a.bvh.gz"}], "fps": 30})
    assert database_id(d, ["h1"]) == database_id(a, ["h1"])
    e = parse_database_spec({"kind": "clips", "clips": [{"bvh": "sample:a"}], "fps": 30})
    assert database_id(e, ["h1"]) == database_id(a, ["h1"])


def test_graph_and_annotated_specs_may_add_mirror_images() -> None:
    for kind in ("graph", "annotated"):
        plain = parse_database_spec({"kind": kind, "clips": [{"bvh": "a.bvh"}]})
        both = parse_database_spec({"kind": kind, "clips": [{"bvh": "a.bvh"}], "mirror": True})
        assert plain.mirror is False and both.mirror is True  # type: ignore[attr-defined]
        assert database_id(plain, ["h1"]) != database_id(both, ["h1"])
        with pytest.raises(ValidationError, match="mirror"):
            parse_database_spec({"kind": kind, "clips": [{"bvh": "a.bvh"}], "mirror": "sideways"})


def test_graph_specs_may_add_time_scaled_copies() -> None:
    plain = parse_database_spec({"kind": "graph", "clips": [{"bvh": "a.bvh"}]})
    copies = parse_database_spec({"kind": "graph", "clips": [{"bvh": "a.bvh"}], "speeds": [0.9, 1.1]})
    assert plain.speeds == [] and copies.speeds == [0.9, 1.1]  # type: ignore[attr-defined]
    assert database_id(plain, ["h1"]) != database_id(copies, ["h1"])
    # no copies: the id the spec had before graph specs had 'speeds' (databases are not built anew)
    canonical = plain.model_dump(mode="json", exclude={"name"})
    del canonical["speeds"]
    canonical["clips"][0].pop("bvh")
    canonical["clips"][0].update(clip="h1", name="a")
    payload = json.dumps({"schema": SCHEMA_VERSION, "spec": canonical}, sort_keys=True, separators=(",", ":"))
    assert database_id(plain, ["h1"]) == hashlib.sha256(payload.encode()).hexdigest()
    for bad, match in (
        ([1.0], "not 1"),
        ([0.4], "in \\[0.5, 2\\]"),
        ([2.5], "in \\[0.5, 2\\]"),
        ([0.9, 1.1, 0.9], "0.9 given more than once"),
        ([float("nan")], "finite number"),
    ):
        with pytest.raises(ValidationError, match=match):
            parse_database_spec({"kind": "graph", "clips": [{"bvh": "a.bvh"}], "speeds": bad})
    with pytest.raises(ValidationError, match="speeds"):
        parse_database_spec({"kind": "annotated", "clips": [{"bvh": "a.bvh"}], "speeds": [0.9]})


def test_job_requests() -> None:
    r = parse_job_request({"engine": "clip", "clip": "walk", "start": 2, "end": 9})
    assert r.engine == "clip" and r.budget_s == 10.0  # type: ignore[attr-defined]
    with pytest.raises(RequestError, match="unknown engine"):
        parse_job_request({"engine": "warp-drive"})
    with pytest.raises(RequestError, match="object"):
        parse_job_request("[1, 2]")
    with pytest.raises(RequestError, match="not valid JSON"):
        parse_job_request("{")
    with pytest.raises(ValidationError, match="end"):
        parse_job_request({"engine": "clip", "clip": "w", "start": 9, "end": 3})
    with pytest.raises(ValidationError, match="less than or equal"):
        parse_job_request({"engine": "clip", "clip": "w", "budget_s": 1e9})


@pytest.mark.parametrize("kind", ["graph", "annotated", "rhythm"])
def test_a_new_mirror_convention_gives_mirrored_databases_new_ids(
    kind: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Databases with mirror images are built anew when the way images are made changes; the others
    keep their ids."""
    from schemas import databases

    plain = parse_database_spec({"kind": kind, "clips": [{"bvh": "a.bvh"}]})
    both = parse_database_spec({"kind": kind, "clips": [{"bvh": "a.bvh"}], "mirror": True})
    before = database_id(plain, ["h1"]), database_id(both, ["h1"])
    monkeypatch.setattr(databases, "MIRROR_VERSION", databases.MIRROR_VERSION + 1)
    assert database_id(plain, ["h1"]) == before[0]
    assert database_id(both, ["h1"]) != before[1]
