"""The shared-directory topology as plain processes: redis-server, `segue serve --redis`, two
`segue worker` processes on one host sharing one data directory (the local store, no
``SEGUE_STORE_URL``), driven through the public API client. The docker-compose topology (no shared
volume: every process on an S3-compatible store, its own disk a cache) is test_topology_s3.py."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from motion import parse_bvh
from motion.samples import sample_path
from service.client import SegueClient

from .conftest import GUARD_S

pytestmark = pytest.mark.slow  # real processes: tests/run.sh runs it with CI=true or SEGUE_SLOW=1

REPO = Path(__file__).resolve().parents[2]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def deployment(redis_url: str, tmp_path: Path) -> Iterator[str]:
    env = dict(
        os.environ,
        SEGUE_DATA_DIR=str(tmp_path / "data"),
        SEGUE_ENGINE_PLUGINS="tests.workers.scripted_engine",
        PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
    )
    port = _free_port()
    segue = [sys.executable, "-m", "service.cli"]
    procs = [
        subprocess.Popen(
            [*segue, "serve", "--port", str(port), "--redis", redis_url, "--log-level", "warning"],
            env=env,
            cwd=REPO,
        ),
        *(
            subprocess.Popen(
                [*segue, "worker", "--redis", redis_url, "--name", f"topology-{i}", "--no-warm"],
                env=env,
                cwd=REPO,
            )
            for i in range(2)
        ),
    ]
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + GUARD_S
        while True:
            try:
                if httpx.get(f"{base}/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline:
                pytest.fail(f"segue serve --redis did not answer /healthz within {GUARD_S} s")
            time.sleep(0.2)
        yield base
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(15)
            except subprocess.TimeoutExpired:
                p.kill()


def test_upload_build_synthesize_stream_download(deployment: str, tmp_path: Path) -> None:
    with SegueClient(deployment) as segue:
        clip = segue.upload_clip(sample_path("walk"))
        db = segue.build_database({"kind": "clips", "clips": [{"bvh": clip.name, "name": "walk"}], "fps": 30})
        assert db.status.value == "ready"
        jobs = [
            segue.submit({"engine": "clip", "database": db.id, "clip": "walk", "start": i, "end": i + 30})
            for i in range(6)
        ]
        for job in jobs:
            events = list(segue.events(job.id))
            assert [e.type.value for e in events][-1] == "done"
            assert [e.id for e in events] == list(range(1, len(events) + 1))
        workers = {
            e.data.get("worker") for job in jobs for e in segue.events(job.id) if e.type.value == "started"
        }
        assert len(workers) >= 1
        out = tmp_path / "walk.bvh"
        segue.result(jobs[0].id, "bvh", out)
        assert parse_bvh(out.read_bytes()).num_frames == 30
        glb = tmp_path / "walk.glb"
        segue.result(jobs[0].id, "glb", glb)
        assert glb.read_bytes()[:4] == b"glTF"
        report = segue.report(jobs[-1].id)
        assert report.provenance[0].clip == "walk" and report.provenance[0].frame == 5
