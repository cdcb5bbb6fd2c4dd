"""Schemathesis over the whole OpenAPI document of a real, populated server (a clip, a database and a
job exist): no server error, and only documented status codes. Its stateful phase follows the
document's links (``service.links``) from uploads, database builds and job submissions to reading
them back, so the fuzz reaches real resources, not only 404s. (The coverage phase, ~3,600 boundary
cases and 25 s, runs in the acceptance check ``robust.py``; this test keeps to the quick phases.)"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl, urlsplit

import httpx
import pytest

from motion.samples import sample_path
from tests.live_server import live_server

pytestmark = pytest.mark.slow  # a real server and schemathesis (about 10 CPU-seconds): CI and SEGUE_SLOW=1

SCHEMATHESIS = shutil.which("schemathesis", path=str(Path(sys.executable).parent)) or shutil.which(
    "schemathesis"
)


def _populate(url: str) -> None:
    walk = sample_path("walk")
    with httpx.Client(base_url=url, timeout=120) as http:  # guards against a hang, not speed bars
        clip = http.post("/v1/clips", files={"file": (walk.name, walk.read_bytes())}).json()
        db = http.post(
            "/v1/databases", json={"kind": "clips", "clips": [{"clip": clip["id"]}], "fps": 30}
        ).json()
        deadline = time.monotonic() + 120
        while http.get(f"/v1/databases/{db['id']}").json()["status"] != "ready":
            assert time.monotonic() < deadline, "the database did not build"
            time.sleep(0.1)
        job = {"engine": "clip", "database": db["id"], "clip": "07_01_walk_daz", "end": 20}
        assert http.post("/v1/jobs", json=job).status_code == 202


def test_schemathesis_finds_no_server_error_and_no_undocumented_status(tmp_path: Path) -> None:
    assert SCHEMATHESIS, "schemathesis is a dev dependency (pip install -e '.[dev]')"
    with live_server(tmp_path, workers=1) as url:
        _populate(url)
        run = subprocess.run(
            [SCHEMATHESIS, "run", f"{url}/openapi.json",
             "--checks", "not_a_server_error,status_code_conformance", "--max-examples", "4",
             "--seed", "7", "--request-timeout", "120", "--workers", "1",
             "--phases", "examples,fuzzing,stateful", "--suppress-health-check", "all",
             "--report", "har", "--report-har-path", str(tmp_path / "run.har")],
            capture_output=True, text=True, timeout=600, cwd=tmp_path,
        )  # fmt: skip
    summary = [line for line in run.stdout.splitlines() if "generated" in line or "Stateful" in line]
    assert run.returncode == 0, run.stdout[-4000:]
    assert summary, run.stdout[-2000:]
    _check_result_route_coverage(json.loads((tmp_path / "run.har").read_text()))


RESULT_ROUTE = re.compile(r"/v1/jobs/[0-9a-f]{32}/result$")
RESULT_QUERY = {"result", "format", "mesh", "feet", "dancer", "animation_only", "fps", "events", "units"}


def _check_result_route_coverage(har: dict[str, Any]) -> None:
    """The run reached the result route of real jobs (ids the links carried: 32 hex digits) with
    ``result`` and at least four more of the route's query parameters, and exported a real result
    (200) at least once: the fuzz covers the route's parameters on real jobs, not only 404s."""
    names: set[str] = set()
    statuses: list[int] = []
    for entry in har["log"]["entries"]:
        url = urlsplit(entry["request"]["url"])
        if entry["request"]["method"] == "GET" and RESULT_ROUTE.search(url.path):
            names.update(name for name, _ in parse_qsl(url.query, keep_blank_values=True))
            statuses.append(int(entry["response"]["status"]))
    assert statuses, "the run never reached the result route of a real job"
    assert "result" in names and len(names & RESULT_QUERY) >= 5, names
    assert 200 in statuses, sorted(set(statuses))
