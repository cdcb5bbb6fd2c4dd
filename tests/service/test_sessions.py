"""The live rhythm session WebSocket (``/v1/sessions/rhythm``) on a small synthetic database.

The app here holds only the sessions router and a store (no job backend: sessions synthesize in
the API process), so the test stays fast."""

from __future__ import annotations

from collections.abc import Iterator
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.testclient import WebSocketDenialResponse
from starlette.websockets import WebSocketDisconnect

from engines.library import library_to_arrays
from engines.rhythm.engine import RhythmEngine
from schemas import DatabaseStatus
from schemas.databases import DatabaseInfo
from schemas.rhythm import RhythmDatabaseSpec
from service.app import create_app
from service.routes import sessions
from service.settings import Settings
from tests.engines.rhythm_synthetic import library
from tests.service.conftest import session_client
from workers.store import Store, now, npz_bytes

DB = "rhythmtest"


class _Quiet:
    def solution(self, solution: object) -> str:
        return "r"

    def progress(self, fraction: float, message: str = "") -> None:
        pass


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    data = tmp_path_factory.mktemp("sessions")
    lib, beats = library(count=2, seconds=8.0)
    spec = RhythmDatabaseSpec.model_validate(
        {
            "kind": "rhythm",
            "clips": [{"bvh": f"{n}.bvh"} for n in lib.names],
            "beats_per_movement": 2,
            "clip_beats": beats,
        }
    )
    arrays = library_to_arrays(lib)
    arrays.update(RhythmEngine.build(spec, lib, _Quiet(), lambda: False))
    store = Store(data)
    info = DatabaseInfo(
        id=DB, kind="rhythm", status=DatabaseStatus.ready, clips=list(lib.names), created_at=now()
    )
    store.put_database_info(info)
    store.put_database_arrays(DB, npz_bytes(arrays))
    store.put_database_info(info.model_copy(update={"id": "notready", "status": DatabaseStatus.building}))
    with session_client(data, store, sessions.router) as c:
        yield c


def test_session_streams_skeleton_then_a_beat_of_frames_per_beat(client: TestClient) -> None:
    with client.websocket_connect(f"/v1/sessions/rhythm?database={DB}&fps=30") as ws:
        skel = ws.receive_json()
        assert skel["type"] == "skeleton" and skel["names"][0] == "hip"
        joints = len(skel["names"])
        assert skel["fps"] == 30 and skel["beats_per_movement"] == 2
        starts = []
        for k in range(3):
            ws.send_json({"type": "beat"})
            msg = ws.receive_json()
            assert msg["type"] == "frames" and msg["beat"] == k
            rot = np.asarray(msg["rotations"])
            root = np.asarray(msg["root"])
            assert rot.shape[1:] == (joints, 4) and root.shape == (rot.shape[0], 3)
            np.testing.assert_allclose(np.linalg.norm(rot, axis=-1), 1.0, atol=1e-3)
            starts.append((msg["start"], rot.shape[0]))
        # batches are contiguous frame ranges
        assert all(s + n == s2 for (s, n), (s2, _) in pairwise(starts))
        ws.send_json({"type": "direction", "heading_deg": 90, "speed": 0.3})
        ws.send_text("{not json")
        assert ws.receive_json()["type"] == "error"
        ws.send_json({"type": "bpm", "bpm": 240})  # server-generated beats every 0.25 s
        got = [ws.receive_json() for _ in range(4)]
        assert [m["type"] for m in got] == ["frames"] * 4
        assert [m["beat"] for m in got] == [3, 4, 5, 6]
        assert all(len(m["root"]) == 8 for m in got)  # 0.25 s at 30 fps, rounded
        ws.send_json({"type": "stop"})
        while True:
            msg = ws.receive_json()
            if msg["type"] == "end":
                break
        assert msg["beats"] >= 7
        with pytest.raises(WebSocketDisconnect) as closed:
            ws.receive_json()
        assert closed.value.code == 1000


@pytest.mark.parametrize(("db", "code"), [("nosuchdb", 4404), ("notready", 4400)])
def test_session_refuses_unknown_or_unready_databases(client: TestClient, db: str, code: int) -> None:
    with (
        client.websocket_connect(f"/v1/sessions/rhythm?database={db}") as ws,
        pytest.raises(WebSocketDisconnect) as closed,
    ):
        ws.receive_json()
    assert closed.value.code == code


def test_live_sessions_per_principal_are_limited(client: TestClient) -> None:
    """The fixture's app allows 2 live sessions per principal: the third is refused with 429."""
    url = f"/v1/sessions/rhythm?database={DB}"
    with client.websocket_connect(url) as first, client.websocket_connect(url) as second:
        assert first.receive_json()["type"] == second.receive_json()["type"] == "skeleton"
        with pytest.raises(WebSocketDenialResponse) as refused, client.websocket_connect(url):
            pass
        assert refused.value.status_code == 429 and refused.value.headers["retry-after"]
    with client.websocket_connect(url) as again:  # the held ones were released
        assert again.receive_json()["type"] == "skeleton"


def test_a_message_over_the_size_limit_ends_the_session(client: TestClient) -> None:
    with client.websocket_connect(f"/v1/sessions/rhythm?database={DB}") as ws:
        assert ws.receive_json()["type"] == "skeleton"
        ws.send_text("x" * 10_000)
        with pytest.raises(WebSocketDisconnect) as closed:
            ws.receive_json()
        assert closed.value.code == 1009


def test_app_registers_the_session_route(tmp_path: Path) -> None:
    app = create_app(Settings(data_dir=tmp_path, allowed_hosts=("localhost", "testserver")))
    assert app.url_path_for("rhythm_session") == "/v1/sessions/rhythm"
