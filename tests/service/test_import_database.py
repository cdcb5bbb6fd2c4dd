"""``segue serve --import DIR``: a database folder ``segue build`` wrote is served under the id the
API gives the same clips and spec (workers.imports)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from service import cli
from service.settings import Settings
from workers.imports import ImportFailure, import_database_dir
from workers.store import Store

from .conftest import wait_events
from .test_api import submit

SPEC = {"kind": "clips", "clips": [{"bvh": "sample:run-09-01"}], "fps": 24}
"""A spec no other test builds (the import must be the first to hold it)."""


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder ``segue build`` wrote."""
    root = tmp_path_factory.mktemp("built")
    (root / "db.json").write_text(json.dumps(SPEC), encoding="utf-8")
    assert cli.main(["build", str(root / "db.json"), "--out", str(root / "db"), "-q"]) == 0
    return root / "db"


def test_an_imported_folder_is_served_under_the_apis_id(
    built: Path, client: TestClient, api_settings: Settings
) -> None:
    folder_id = json.loads((built / "info.json").read_text())["id"]
    info, new = import_database_dir(Store(api_settings.data_dir), built, ["local"])
    assert new and info.id == folder_id and info.status == "ready" and info.build_job is None
    db = client.get(f"/v1/databases/{folder_id}").json()
    assert db["status"] == "ready" and db["clips"] == ["run-09-01"]
    assert db["summary"]["skeleton"]["joints"] and db["summary"]["units"] == "m"
    # the same spec posted to the API is the same database, not a second build
    r = client.post("/v1/databases", json=SPEC)
    assert r.status_code == 200 and r.json()["id"] == folder_id, r.text
    job = submit(client, {"engine": "scripted", "database": folder_id, "steps": 1, "step_s": 0})
    assert wait_events(client, job["id"])[-1]["type"] == "done"
    # importing again: nothing new
    assert import_database_dir(Store(api_settings.data_dir), built, ["local"])[1] is False


def test_serve_import_imports_before_serving(
    built: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import uvicorn

    served: list[Any] = []
    monkeypatch.setattr(uvicorn, "run", lambda app, **kw: served.append(kw))
    data = tmp_path / "data"
    assert (
        cli.main(["serve", "--data", str(data), "--import", str(built), "--port", "8123", "--no-warm"]) == 0
    )
    assert served and served[0]["port"] == 8123
    folder_id = json.loads((built / "info.json").read_text())["id"]
    assert f"imported clips database {folder_id[:12]} (1 clip) from {built}" in capsys.readouterr().err
    assert Store(data).database_info(folder_id).status == "ready"
    with Store(data).open_database(folder_id) as stored, np.load(built / "data.npz") as written:
        assert sorted(stored) == sorted(written.files)
        for name in written.files:  # the same arrays, bit for bit
            assert stored[name].dtype == written[name].dtype
            assert np.array_equal(stored[name], written[name])


def test_a_folder_that_is_not_what_it_says_is_refused(
    built: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = Store(tmp_path / "data")
    with pytest.raises(ImportFailure, match="not a database folder written by segue build"):
        import_database_dir(store, tmp_path, ["local"])
    edited = tmp_path / "edited"
    shutil.copytree(built, edited)
    spec = json.loads((edited / "spec.json").read_text())
    spec["fps"] = 60
    (edited / "spec.json").write_text(json.dumps(spec))
    with pytest.raises(ImportFailure, match="its spec and clips give"):
        import_database_dir(store, edited, ["local"])
    assert store.list_databases() == []
    # the command line names the problem in one line, exit status 2
    assert cli.main(["serve", "--data", str(tmp_path / "data"), "--import", str(edited)]) == 2
    assert "segue: error:" in capsys.readouterr().err
