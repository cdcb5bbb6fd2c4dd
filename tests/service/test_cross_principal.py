"""No facts about another principal (issue 40, item 4): uploading bytes another principal holds in
other units, or deleting a database another principal's jobs use, answers as for data the caller
alone holds (its own units; its hold released), and names none of the other's objects; the
caller's own conflicts are still explained (its own clip and units, its own jobs)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from fastapi.testclient import TestClient

from motion.units import METRES_PER_UNIT
from workers.settings import Settings

from .test_api_bounded import _bvh

GUARD_S = 120.0


def _principals(override_settings: Callable[..., Settings]) -> tuple[dict[str, str], dict[str, str]]:
    # principals of their own: other tests' principals must not hold what these leave behind
    override_settings(api_tokens=("erin:te", "frank:tf"))
    return {"Authorization": "Bearer te"}, {"Authorization": "Bearer tf"}


def _upload(client: TestClient, data: bytes, name: str, who: dict[str, str], units: str | None) -> Any:
    params = {"units": units} if units else {}
    return client.post("/v1/clips", params=params, files={"file": (name, data)}, headers=who)


def test_bytes_another_principal_holds_in_other_units_answer_as_new(
    client: TestClient, override_settings: Callable[..., Settings]
) -> None:
    erin, frank = _principals(override_settings)
    shared, alone = _bvh(1.0 + time.time_ns() % 997 / 1e4), _bvh(2.0 + time.time_ns() % 991 / 1e4)
    hers = _upload(client, shared, "erin.bvh", erin, "cm")
    assert hers.status_code == 201, hers.text
    # frank, in metres: as for bytes he alone holds (201, his units), nothing of erin's
    his = _upload(client, shared, "frank.bvh", frank, "m")
    control = _upload(client, alone, "frank-alone.bvh", frank, "m")
    assert his.status_code == control.status_code == 201, his.text
    mine = his.json()
    assert mine["id"] == hers.json()["id"] and mine["units"] == "m" and mine["name"] == "frank.bvh"
    scale = METRES_PER_UNIT["m"] / METRES_PER_UNIT["cm"]
    assert abs(mine["height_m"] - hers.json()["height_m"] * scale) <= 1e-3 * mine["height_m"]
    assert "cm" not in his.text and "erin" not in his.text
    # each sees its own units
    assert client.get(f"/v1/clips/{mine['id']}", headers=erin).json()["units"] == "cm"
    assert client.get(f"/v1/clips/{mine['id']}", headers=frank).json()["units"] == "m"
    # his own conflict is still explained: his clip, his units
    again = _upload(client, shared, "frank.bvh", frank, "cm")
    assert again.status_code == 409 and again.json()["error"]["code"] == "units_conflict"
    assert again.json()["error"]["details"] == {"clip": mine["id"], "units": "m"}
    assert _upload(client, shared, "frank.bvh", frank, "m").status_code == 200
    # a database each builds from the clip reads it in the builder's units
    for who, name, units in ((erin, "erin.bvh", "cm"), (frank, "frank.bvh", "m")):
        spec = {"kind": "clips", "clips": [{"bvh": name}], "fps": 30}
        db = client.post("/v1/databases", json=spec, headers=who).json()["id"]
        _wait(client, f"/v1/databases/{db}", who, lambda d: d["status"] == "ready")
        summary = client.get(f"/v1/databases/{db}", headers=who).json()["summary"]
        assert [c["source_units"] for c in summary["clips"]] == [units]
    # without units, his upload reads as a first upload would (the guess), not as erin declared
    other = _bvh(1.5 + time.time_ns() % 983 / 1e4)
    first = _upload(client, other, "erin2.bvh", erin, None).json()  # the guess
    declared = "mm" if first["units"] != "mm" else "cm"
    assert client.delete(f"/v1/clips/{first['id']}", headers=erin).status_code == 204
    assert _upload(client, other, "erin2.bvh", erin, declared).json()["units"] == declared
    guessed = _upload(client, other, "frank2.bvh", frank, None).json()
    assert guessed["units"] == first["units"]
    # the height is converted from the shared record's (rounded to 0.1 mm in its unit)
    assert abs(guessed["height_m"] - first["height_m"]) <= 1e-3 * first["height_m"]


def _wait(client: TestClient, path: str, who: dict[str, str], done: Callable[[dict[str, Any]], bool]) -> None:
    deadline = time.monotonic() + GUARD_S
    while not done(client.get(path, headers=who).json()):
        assert time.monotonic() < deadline, f"{path} did not reach the state in time"
        time.sleep(0.05)


def test_deleting_a_database_another_principals_jobs_use_names_none_of_them(
    client: TestClient, override_settings: Callable[..., Settings]
) -> None:
    erin, frank = _principals(override_settings)
    data = _bvh(3.0 + time.time_ns() % 977 / 1e4)
    for who in (erin, frank):
        assert _upload(client, data, "walk.bvh", who, None).status_code in (200, 201)
    spec = {"kind": "clips", "clips": [{"bvh": "walk.bvh"}], "fps": 30}
    db = client.post("/v1/databases", json=spec, headers=erin).json()["id"]
    _wait(client, f"/v1/databases/{db}", erin, lambda d: d["status"] == "ready")
    assert client.post("/v1/databases", json=spec, headers=frank).json()["id"] == db
    long = {"engine": "scripted", "database": db, "steps": 400, "step_s": 0.25}
    job = client.post("/v1/jobs", json=long, headers=erin).json()["id"]
    try:
        # frank's delete: his hold goes, as for a database he alone holds; erin's job is not named
        gone = client.delete(f"/v1/databases/{db}", headers=frank)
        assert gone.status_code == 204 and job not in gone.text
        assert client.get(f"/v1/databases/{db}", headers=frank).status_code == 404
        assert client.get(f"/v1/databases/{db}", headers=erin).json()["status"] == "ready"
        # his own jobs on it are still his conflict, named (only his)
        assert client.post("/v1/databases", json=spec, headers=frank).json()["id"] == db
        his = client.post("/v1/jobs", json=long, headers=frank).json()["id"]
        try:
            refused = client.delete(f"/v1/databases/{db}", headers=frank)
            assert refused.status_code == 409
            assert refused.json()["error"]["code"] == "database_in_use"
            assert refused.json()["error"]["details"] == {"jobs": [his]}
            assert job not in refused.text
        finally:
            client.post(f"/v1/jobs/{his}/cancel", headers=frank)
        # erin's own: named as before
        hers = client.delete(f"/v1/databases/{db}", headers=erin)
        assert hers.status_code == 409 and hers.json()["error"]["details"] == {"jobs": [job]}
    finally:
        client.post(f"/v1/jobs/{job}/cancel", headers=erin)
