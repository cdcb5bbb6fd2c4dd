"""Result downloads for game engines over HTTP: units per target and as override, in place, events."""

from __future__ import annotations

import io
import json
import struct
from typing import Any

import numpy as np
from fastapi.testclient import TestClient

from motion import parse_bvh

from .conftest import WALK_CLIP, wait_events
from .test_api import error_of, submit


def _glb_json(data: bytes) -> dict[str, Any]:
    n = struct.unpack_from("<I", data, 12)[0]
    doc: dict[str, Any] = json.loads(data[20 : 20 + n])
    return doc


def test_result_units_in_place_and_events(client: TestClient, walk_db: dict[str, Any]) -> None:
    job = submit(
        client, {"engine": "clip", "database": walk_db["id"], "clip": WALK_CLIP, "start": 0, "end": 80}
    )
    last = wait_events(client, job["id"])[-1]
    assert last["type"] == "done", last["data"]
    url = f"/v1/jobs/{job['id']}/result"

    metres = parse_bvh(client.get(url, params={"format": "bvh"}).content, source="m.bvh", units="m")
    cm = parse_bvh(
        client.get(url, params={"format": "bvh", "units": "cm"}).content, source="c.bvh", units="cm"
    )
    np.testing.assert_allclose(cm.global_positions() / 100, metres.global_positions(), atol=1e-5)
    unreal = client.get(url, params={"format": "json", "target": "unreal"}).json()
    assert unreal["convention"]["units"] == "cm"
    overridden = client.get(url, params={"format": "json", "target": "unreal", "units": "m"}).json()
    assert overridden["convention"]["units"] == "m"
    with np.load(io.BytesIO(client.get(url, params={"format": "npz", "target": "unreal"}).content)) as z:
        assert str(z["units"]) == "cm"

    glb = _glb_json(client.get(url, params={"format": "glb", "in_place": True, "events": "contacts"}).content)
    (skin,) = glb["skins"]
    origin, ground, hips = skin["joints"][:3]
    assert glb["nodes"][origin]["children"][:2] == [ground, hips]  # in place: hips beside the ground
    events = glb["animations"][0]["extras"]["events"]
    assert events and {e["type"] for e in events} == {"contact"}
    frames = client.get(url, params={"format": "json", "events": "all", "fps": 15}).json()
    assert frames["events"] and all(e["time_s"] <= 79 / 30 + 1e-6 for e in frames["events"])

    error_of(client.get(url, params={"format": "glb", "units": "cm"}), 422, "export_failed")
    error_of(client.get(url, params={"format": "bvh", "in_place": True}), 422, "export_failed")
    error_of(client.get(url, params={"format": "bvh", "events": "contacts"}), 422, "export_failed")
    err = error_of(client.get(url, params={"format": "glb", "events": "footsteps"}), 422)
    assert "footsteps" in err["message"]
    error_of(client.get(url, params={"format": "glb", "units": "furlong"}), 422, "invalid_request")
