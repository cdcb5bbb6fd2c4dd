"""Fixtures for the API tests: one app (embedded backend, one worker, the scripted engine) per
session on a temporary data dir, a TestClient, and a ``clips`` database built from a CMU sample."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from fastapi import APIRouter, FastAPI
from fastapi.testclient import TestClient

from motion.samples import sample_path
from service.app import create_app
from service.deps import app_settings
from service.errors import install_error_handlers
from service.limits import SessionQuota
from service.settings import Settings
from workers.engine_cache import EngineCache
from workers.store import Store

REPO = Path(__file__).resolve().parents[2]
PLUGINS = "tests.workers.scripted_engine"
WALK = sample_path("walk")  # 07_01_walk_daz.bvh.gz, 317 frames at 120 fps
WALK_CLIP = "07_01_walk_daz"  # its name in databases (file name without .bvh.gz)


@pytest.fixture(scope="session")
def api_settings(tmp_path_factory: pytest.TempPathFactory) -> Settings:
    """Settings of the session's app: a fresh data dir, one worker, the scripted engine."""
    return Settings(
        data_dir=tmp_path_factory.mktemp("segue-data"),
        workers=1,
        engine_plugins=PLUGINS,
        allowed_hosts=("localhost", "testserver"),  # TestClient WebSockets use ws://testserver
        job_grace_s=600.0,  # the hard time limit past budget_s: a hang guard, not a speed bar
    )


@pytest.fixture(scope="session")
def app(api_settings: Settings) -> FastAPI:
    return create_app(api_settings)


@pytest.fixture(scope="session")
def client(app: FastAPI) -> Iterator[TestClient]:
    """A TestClient with the app started (worker processes spawned once per session)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
        mp.setenv("SEGUE_ENGINE_PLUGINS", PLUGINS)
        with TestClient(app, base_url="http://localhost") as test_client:
            yield test_client


@pytest.fixture
def override_settings(app: FastAPI, api_settings: Settings) -> Iterator[Callable[..., Settings]]:
    """``override_settings(api_tokens=("t",))``: what routes see until the test ends."""

    def apply(**changes: Any) -> Settings:
        changed = api_settings.model_copy(update=changes)
        app.dependency_overrides[app_settings] = lambda: changed
        return changed

    yield apply
    app.dependency_overrides.pop(app_settings, None)


@contextmanager
def no_overrides(app: FastAPI) -> Iterator[None]:
    saved = dict(app.dependency_overrides)
    app.dependency_overrides.clear()
    try:
        yield
    finally:
        app.dependency_overrides.update(saved)


def wait_events(client: TestClient, job_id: str, after: int = 0) -> list[dict[str, Any]]:
    """Every event of a job over the WebSocket, through the terminal one (close code checked)."""
    out: list[dict[str, Any]] = []
    with client.websocket_connect(f"/v1/jobs/{job_id}/events?after={after}") as ws:
        while True:
            event = ws.receive_json()
            out.append(event)
            if event["type"] in ("done", "failed", "cancelled"):
                message = ws.receive()
                assert message["type"] == "websocket.close" and message["code"] == 1000, message
                return out


@pytest.fixture(scope="session")
def walk_clip(client: TestClient) -> dict[str, Any]:
    """The walk sample, uploaded (gzip) as multipart."""
    r = client.post("/v1/clips", files={"file": (WALK.name, WALK.read_bytes())})
    assert r.status_code in (200, 201), r.text
    return dict(r.json())


@pytest.fixture(scope="session")
def walk_db(client: TestClient, walk_clip: dict[str, Any]) -> dict[str, Any]:
    """A ready ``clips`` database of the walk at 30 fps (built through the API)."""
    return ready_database(client, {"kind": "clips", "clips": [{"bvh": walk_clip["name"]}], "fps": 30})


def ready_database(client: TestClient, spec: dict[str, Any]) -> dict[str, Any]:
    """Build ``spec`` through the API and wait until it is ready; its database info."""
    r = client.post("/v1/databases", json=spec)
    assert r.status_code in (200, 202), r.text
    db = r.json()
    if db["status"] != "ready":
        events = wait_events(client, db["build_job"])
        assert events[-1]["type"] == "done", events
    db = client.get(f"/v1/databases/{db['id']}").json()
    assert db["status"] == "ready", db
    return dict(db)


@contextmanager
def session_client(data: Path, store: Store, router: APIRouter) -> Iterator[TestClient]:
    """A client of a bare app serving one live-session ``router`` on ``store`` (data dir ``data``):
    error handlers, a quota of 2 sessions and an engine cache, as the real app wires them."""
    app = FastAPI()
    app.state.settings = Settings(data_dir=data, allowed_hosts=("localhost", "testserver"))
    app.state.store = store
    app.state.session_quota = SessionQuota(2)
    app.state.engines = EngineCache()
    install_error_handlers(app)
    app.include_router(router)
    with TestClient(app, base_url="http://localhost") as c:
        yield c
