"""The live control session WebSocket (``/v1/sessions/control``) on a small synthetic walk database.

The app here holds only the session routers and a store (sessions synthesize in the API process)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from engines.base import CollectingEmitter, Run
from engines.control.engine import ControlEngine
from engines.library import library_to_arrays
from motion.ground import ground_frames
from schemas import DatabaseStatus
from schemas.control import ControlRequest
from schemas.databases import DatabaseInfo
from service.routes import control_sessions
from tests.engines.test_control import walk_engine
from tests.motion.synthetic import walking_biped
from tests.service.conftest import session_client
from workers.store import Store, now, npz_bytes

DB = "walktest"


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    data = tmp_path_factory.mktemp("control-sessions")
    engine = walk_engine()
    arrays = dict(engine.arrays)
    arrays.update(library_to_arrays(engine.library))
    store = Store(data)
    info = DatabaseInfo(
        id=DB, kind="control", status=DatabaseStatus.ready, clips=list(engine.library.names), created_at=now()
    )
    store.put_database_info(info)
    store.put_database_arrays(DB, npz_bytes(arrays))
    store.put_database_info(info.model_copy(update={"id": "rhythmdb", "kind": "rhythm"}))
    with session_client(data, store, control_sessions.router) as c:
        yield c


def test_a_path_streamed_over_the_websocket_is_walked_with_a_fixed_latency(client: TestClient) -> None:
    held = walking_biped(150, speed=1.1, heading_deg=-30.0, seed=9)
    path, _ = ground_frames(held)
    with client.websocket_connect(f"/v1/sessions/control?database={DB}&latency_s=1") as ws:
        hello = ws.receive_json()
        assert hello["type"] == "skeleton" and hello["control"] == "path"
        assert hello["latency_frames"] == 30 and hello["fps"] == 30
        joints = len(hello["names"])
        ws.send_json({"type": "pose", "frames": [[[0, 0, 0]]]})  # a path database takes a path
        assert ws.receive_json()["type"] == "error"
        ws.send_text("{not json")
        assert ws.receive_json()["type"] == "error"
        roots, sent = [], 0
        for i in range(0, 150, 10):
            ws.send_json({"type": "path", "points": path[i : i + 10].tolist()})
            msg = ws.receive_json()
            assert msg["type"] == "frames" and msg["start"] == sent
            rot = np.asarray(msg["rotations"]).reshape(-1, joints, 4)
            np.testing.assert_allclose(np.linalg.norm(rot, axis=-1), 1.0, atol=1e-3)
            roots.append(np.asarray(msg["root"]).reshape(-1, 3))
            sent += rot.shape[0]
            if i + 10 >= 90:  # the stated latency, exactly, once windows are long enough
                assert sent == i + 10 - 30
        ws.send_json({"type": "stop"})
        last = ws.receive_json()
        roots.append(np.asarray(last["root"]).reshape(-1, 3))
        end = ws.receive_json()
        assert end["type"] == "end" and end["frames"] == 150
        with pytest.raises(WebSocketDisconnect) as closed:
            ws.receive_json()
        assert closed.value.code == 1000
    root = np.concatenate(roots)
    assert root.shape == (150, 3)
    # close to the offline answer for the same path (the walker follows the path either way)
    request = ControlRequest.model_validate(
        {"engine": "control", "control": {"trajectory": {"fps": 30, "points": path.tolist()}}}
    )
    engine: ControlEngine = walk_engine()
    out = CollectingEmitter()
    engine.search(request, Run(5.0, emit=out))
    offline = out.solutions[-1].motion.global_positions()[:, 0] * out.solutions[-1].motion.metres_per_unit
    assert float(np.linalg.norm((root - offline)[:, [0, 2]], axis=-1).mean()) < 0.15


@pytest.mark.parametrize(("db", "code"), [("nosuchdb", 4404), ("rhythmdb", 4400)])
def test_unknown_or_other_kinds_of_databases_are_refused(client: TestClient, db: str, code: int) -> None:
    with (
        client.websocket_connect(f"/v1/sessions/control?database={db}") as ws,
        pytest.raises(WebSocketDisconnect) as closed,
    ):
        ws.receive_json()
    assert closed.value.code == code
