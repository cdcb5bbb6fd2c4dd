"""The add-on's plain-Python client outside Blender, against a real ``segue serve``: the HTTP
client, the job thread (anytime solutions, cancel keeping the best), the local service, and the
zip ``segue blender-addon`` writes."""

from __future__ import annotations

import ast
import subprocess
import tomllib
import zipfile
from pathlib import Path

import pytest

from integrations.blender.segue_blender import gltf
from integrations.blender.segue_blender.client import SegueClient, SegueError
from integrations.blender.segue_blender.jobs import JobRunner, Message
from integrations.blender.segue_blender.local_service import LocalService, free_port

from .conftest import SEGUE, Serve

WALKS = {
    "kind": "graph", "fps": 30, "name": "walks",
    "clips": [{"bvh": f"sample:{n}"} for n in ("walk", "walk-05-01", "walk-10-04", "walk-12-02")],
}  # fmt: skip


def test_the_zip_installs_as_an_extension_and_as_a_legacy_addon(addon_zip: Path, tmp_path: Path) -> None:
    with zipfile.ZipFile(addon_zip) as zf:
        names = zf.namelist()
        manifest = tomllib.loads(zf.read("segue_blender/blender_manifest.toml").decode())
        init = ast.parse(zf.read("segue_blender/__init__.py"))
    assert all(n.startswith("segue_blender/") for n in names)  # one folder: a legacy add-on's package
    assert {"segue_blender/__init__.py", "segue_blender/ops.py", "segue_blender/client.py"} <= set(names)
    assert not any("__pycache__" in n for n in names)
    assert manifest["id"] == "segue_blender" and manifest["type"] == "add-on"
    assert manifest["blender_version_min"] == "4.2.0" and "network" in manifest["permissions"]
    bl_info = next(
        ast.literal_eval(n.value)
        for n in init.body
        if isinstance(n, ast.Assign) and n.targets[0].id == "bl_info"
    )  # type: ignore[attr-defined]
    assert bl_info["blender"] == (4, 2, 0)
    assert ".".join(map(str, bl_info["version"])) == manifest["version"]
    again = tmp_path / "again.zip"
    subprocess.run(
        [str(SEGUE), "blender-addon", "--out", str(again)], check=True, capture_output=True, timeout=60
    )
    assert again.read_bytes() == addon_zip.read_bytes()  # the same sources, the same zip
    r = subprocess.run([str(SEGUE), "blender-addon", "--out", str(tmp_path / "addon.tar")],
                       capture_output=True, text=True, timeout=60, check=False)  # fmt: skip
    assert r.returncode == 2 and "the add-on is a .zip file" in r.stderr


@pytest.fixture(scope="module")
def walks(serve: Serve) -> str:
    with serve.client() as c:
        return str(c.build_database(WALKS, timeout=600).id)


def _drain(runner: JobRunner, guard: float = 120.0) -> list[Message]:
    runner.join(guard)
    assert not runner.is_alive(), "the job thread did not end (hang guard)"
    out = []
    while not runner.messages.empty():
        out.append(runner.messages.get())
    return out


def test_the_client_names_errors_and_unreachable_servers(serve: Serve) -> None:
    client = SegueClient(serve.url)
    with pytest.raises(SegueError) as err:
        client.database("nope")
    assert err.value.status == 404 and err.value.code == "not_found"
    with pytest.raises(SegueError) as err:
        SegueClient(f"http://127.0.0.1:{free_port()}", timeout=2).clips()
    assert err.value.status == 0 and err.value.code == "unreachable"
    with pytest.raises(SegueError, match="not an http"):
        SegueClient("ftp://example")


def test_a_job_thread_shows_each_new_best_and_ends_with_its_report(serve: Serve, walks: str) -> None:
    client = SegueClient(serve.url)
    request = {"engine": "graph", "database": walks, "frames": 120, "seed": 4, "rounds": 10,
               "constraints": [{"type": "body", "frame": 0, "position": [0, 0]},
                               {"type": "body", "frame": 119, "position": [0.5, 4.0]}]}  # fmt: skip
    runner = JobRunner(
        client,
        lambda: request,
        download=lambda rid: client.result(runner.job_id or "", format="glb", result=rid),
        prepare=lambda raw: gltf.animation(*gltf.split_glb(raw)).times,
    )
    runner.start()
    messages = _drain(runner)
    kinds = [m.kind for m in messages]
    assert kinds[0] == "submitted" and kinds[-1] == "end", kinds
    assert messages[-1].data["type"] == "done"
    shown = [m for m in messages if m.kind == "solution"]
    assert shown and all(len(m.prepared) == 120 for m in shown)  # each a whole result, parsed in the thread
    ids = [int(m.data["result"].lstrip("r")) for m in shown]
    assert (
        ids == sorted(set(ids)) and shown[-1].data["result"] == messages[-1].data["result"]
    )  # the best last
    reports = [m for m in messages if m.kind == "report"]
    assert [r.data["result"] for r in reports] == [m.data["result"] for m in shown]
    assert "body[1]" in reports[-1].data["report"]["constraint_errors"]


def test_cancel_keeps_the_best_so_far(serve: Serve, walks: str) -> None:
    client = SegueClient(serve.url)
    # long by its work (a search also ends when it converges): a minute of motion, the goal 40 m away
    goal = {"type": "body", "frame": 1439, "position": [30.0, 28.0]}
    request = {"engine": "graph", "database": walks, "frames": 1440, "seed": 1, "rounds": None,
               "budget_s": 300, "constraints": [goal]}  # fmt: skip
    seen: list[str] = []

    def download(rid: str) -> bytes:
        seen.append(rid)
        runner.cancel()  # once a solution shows
        return client.result(runner.job_id or "", format="glb", result=rid)

    runner = JobRunner(client, request, download=download)
    runner.start()
    messages = _drain(runner)
    end = messages[-1]
    assert end.kind == "end" and end.data["type"] == "cancelled", end.data
    assert seen and end.data["result"]  # the best so far is kept, and downloads
    assert client.result(runner.job_id or "", format="bvh", result=end.data["result"])[:9] == b"HIERARCHY"


def test_a_job_thread_reports_a_refused_request(serve: Serve, walks: str) -> None:
    runner = JobRunner(SegueClient(serve.url), {"engine": "graph", "database": walks})
    runner.start()
    (msg,) = _drain(runner)
    assert msg.kind == "error" and msg.data["status"] == 422 and "frames" in msg.data["message"]


def test_a_local_service_starts_on_a_free_port_and_stops(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Blender's environment, not the test session's: the service tests' session-wide fixture sets
    # SEGUE_ENGINE_PLUGINS to a test module the service could not import without their PYTHONPATH
    for var in ("SEGUE_ENGINE_PLUGINS", "SEGUE_API_TOKENS", "SEGUE_REDIS_URL"):
        monkeypatch.delenv(var, raising=False)
    with pytest.raises(SegueError, match="no segue executable"):
        LocalService(tmp_path / "nothing", tmp_path / "data").start()
    service = LocalService(SEGUE, tmp_path / "data")
    url = service.start()
    try:
        assert SegueClient(url).health()["ok"] is True
        pid = service.process.pid if service.process else -1
    finally:
        service.stop()
    assert service.process is None
    assert not Path(f"/proc/{pid}").exists() or _zombie(pid)
    assert url.startswith("http://127.0.0.1:")


def _zombie(pid: int) -> bool:
    try:
        return "Z" in Path(f"/proc/{pid}/status").read_text().split("State:")[1].split()[0]
    except (OSError, IndexError):
        return True
