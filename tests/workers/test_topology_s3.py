"""Three hosts as plain processes (issue 26's done-when): `segue serve --redis` and three
`segue worker`s, each with its own empty data directory (a host's disk: a cache only), sharing only a
redis-server and an S3-protocol server (``moto_server``; ``SEGUE_STORE_URL=s3://...`` with the
standard AWS variables, ``AWS_ENDPOINT_URL``), driven through the public API client.

* Clips uploaded, a graph database built by a worker, six graph jobs run while one worker is
  SIGKILLed mid-job; every result (BVH, GLB) and report fetched through the API.
* A worker SIGSTOPped (with its engine process) past the reclaim time and resumed (SIGCONT) publishes
  nothing: the job ends once, and every event after the last ``started`` carries that start's attempt.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import pytest
import redis

from motion import parse_bvh
from motion.samples import sample_path
from schemas import EventType, JobEvent, JobStatus
from service.client import SegueClient
from tests.processes import engine_children
from workers.redis_keys import RedisKeys

from .conftest import GUARD_S, PLUGINS, REPO, wait_for

pytestmark = pytest.mark.slow  # real processes: tests/run.sh runs it with CI=true or SEGUE_SLOW=1

KEYS = RedisKeys()
WORKERS = ("host-a", "host-b", "host-c")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Hosts:
    """The processes of one deployment: the API's URL, the workers by name, their logs."""

    base: str
    workers: dict[str, subprocess.Popen[bytes]]
    logs: dict[str, Path]
    data_dirs: dict[str, Path] = field(default_factory=dict)


@pytest.fixture
def hosts(redis_url: str, s3_url: str, tmp_path: Path) -> Iterator[Hosts]:
    """An API and three workers: each its own empty ``SEGUE_DATA_DIR``; the store is ``s3_url``
    (the AWS variables come from the ``s3_endpoint`` fixture's environment)."""
    common = dict(
        os.environ,
        SEGUE_STORE_URL=s3_url,
        SEGUE_ENGINE_PLUGINS=PLUGINS,
        PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
    )
    assert common.get("AWS_ENDPOINT_URL"), "the s3_endpoint fixture sets the AWS variables"
    segue = [sys.executable, "-m", "service.cli"]
    port = _free_port()
    data_dirs = {name: tmp_path / name for name in ("api", *WORKERS)}
    api = subprocess.Popen(
        [*segue, "serve", "--port", str(port), "--redis", redis_url, "--log-level", "warning"],
        env=common | {"SEGUE_DATA_DIR": str(data_dirs["api"])},
        cwd=REPO,
    )
    # a hung worker: its heartbeat expires after 5 s, a pending entry idle 5 s is taken over (both
    # refreshed every 0.2 s: a live worker a loaded machine leaves unscheduled for a second keeps its
    # job; with 1 s and 2 s it could lose it as if it had hung)
    worker_env = {
        "SEGUE_HEARTBEAT_S": "0.2",
        "SEGUE_HEARTBEAT_TTL_S": "5.0",
        "SEGUE_RECLAIM_IDLE_S": "5",
        "SEGUE_BLOCK_MS": "100",
        "SEGUE_LOG_LEVEL": "WARNING",
    }
    logs = {name: tmp_path / f"{name}.log" for name in WORKERS}
    workers: dict[str, subprocess.Popen[bytes]] = {}
    for name in WORKERS:
        with logs[name].open("ab") as sink:
            workers[name] = subprocess.Popen(
                [*segue, "worker", "--redis", redis_url, "--name", name, "--no-warm"],
                env=common | worker_env | {"SEGUE_DATA_DIR": str(data_dirs[name])},
                cwd=REPO,
                stderr=sink,
            )
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
        yield Hosts(base, workers, logs, data_dirs)
    finally:
        for proc in (api, *workers.values()):
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGCONT)  # a test that failed while a worker was stopped
                proc.send_signal(signal.SIGKILL)
        for proc in (api, *workers.values()):
            proc.wait(timeout=GUARD_S)


def _running(client: redis.Redis, worker: str) -> str | None:
    """The job a worker's heartbeat names (None when idle or silent)."""
    raw = client.get(KEYS.worker(worker))
    return json.loads(raw).get("job") if raw else None


def _files_under(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file()) if root.exists() else []


def test_three_hosts_share_only_redis_and_the_object_store(
    hosts: Hosts, redis_url: str, tmp_path: Path
) -> None:
    client = redis.Redis.from_url(redis_url, decode_responses=True)
    with SegueClient(hosts.base) as segue:
        clip = segue.upload_clip(sample_path("walk"))
        db = segue.build_database({"kind": "graph", "clips": [{"clip": clip.id, "name": "walk"}], "fps": 30})
        assert db.status.value == "ready"
        build = segue.job(db.build_job) if db.build_job else None
        assert build is not None and build.status == JobStatus.done
        builders = [e.data.get("worker") for e in segue.events(build.id) if e.type == EventType.started]
        assert builders and set(builders) <= set(WORKERS)  # built by a worker, not the API
        jobs = [
            segue.submit({"engine": "graph", "database": db.id, "frames": 60 + k, "rounds": 3, "seed": k})
            for k in range(6)
        ]
        victim = wait_for(
            lambda: next((w for w in WORKERS if _running(client, w) in {j.id for j in jobs}), None),
            interval=0.01,
            what="a worker running one of the six jobs",
        )
        hosts.workers[victim].send_signal(signal.SIGKILL)
        hosts.workers[victim].wait(timeout=GUARD_S)
        for job in jobs:
            events = list(segue.events(job.id))
            assert [e.id for e in events] == list(range(1, len(events) + 1))
            assert [e.type for e in events if e.type.terminal] == [EventType.done]
            assert events[-1].type == EventType.done
            last = max(i for i, e in enumerate(events) if e.type == EventType.started)
            assert {e.attempt for e in events[last:]} == {events[last].attempt}
            bvh = segue.result(job.id, "bvh")
            assert parse_bvh(bvh).num_frames == 60 + jobs.index(job)
            assert segue.result(job.id, "glb")[:4] == b"glTF"
            report = segue.report(job.id)
            assert report.provenance and {p.clip for p in report.provenance} == {"walk"}
    client.close()
    # nothing durable on the API host's disk: it answered every fetch from the object store
    assert not any(p.endswith((".bvh", ".glb", ".npy", ".npz")) for p in _files_under(hosts.data_dirs["api"]))


def test_a_hung_worker_resumed_publishes_nothing_across_hosts(hosts: Hosts, redis_url: str) -> None:
    client = redis.Redis.from_url(redis_url, decode_responses=True)
    stopped: list[int] = []
    try:
        with SegueClient(hosts.base) as segue:
            clip = segue.upload_clip(sample_path("walk"))
            spec = {"kind": "clips", "clips": [{"clip": clip.id, "name": "walk"}], "fps": 30}
            db = segue.build_database(spec)
            job = segue.submit({"engine": "scripted", "database": db.id, "steps": 60, "step_s": 0.1})

            def solutions() -> int:
                return sum(e.type == EventType.solution for e in segue.poll_events(job.id))

            wait_for(lambda: solutions() >= 2, interval=0.05, what="the first run's solutions")
            hung = wait_for(
                lambda: next((w for w in WORKERS if _running(client, w) == job.id), None),
                what="the worker running the job",
            )
            stopped = [hosts.workers[hung].pid, *engine_children(hosts.workers[hung].pid)]
            for pid in stopped:
                os.kill(pid, signal.SIGSTOP)

            def second_start() -> JobEvent | None:
                starts = [e for e in segue.poll_events(job.id) if e.type == EventType.started]
                return starts[-1] if len(starts) >= 2 else None

            start2 = wait_for(second_start, interval=0.1, what="another worker to run attempt 2")
            assert start2.attempt == 2 and start2.data["worker"] != hung
            for pid in stopped:
                os.kill(pid, signal.SIGCONT)
            stopped = []
            list(segue.events(job.id))  # to the end
            wait_for(lambda: _running(client, hung) is None, what="the resumed worker to drop its stale run")
            wait_for(lambda: client.xlen(KEYS.jobs) == 0, what="the entry acked and deleted")
            events = segue.poll_events(job.id)  # the whole log, after the resumed worker had its chance
            info = segue.job(job.id)
            assert parse_bvh(segue.result(job.id, "bvh")).num_frames > 0
    finally:
        for pid in stopped:
            os.kill(pid, signal.SIGCONT)
        client.close()
    assert [e.id for e in events] == list(range(1, len(events) + 1))
    terminals = [e for e in events if e.type.terminal]
    assert len(terminals) == 1 and terminals[0] is events[-1] and terminals[0].type == EventType.done
    last_start = max(i for i, e in enumerate(events) if e.type == EventType.started)
    assert {e.attempt for e in events[last_start:]} == {events[last_start].attempt} == {2}
    assert [e.attempt for e in events] == sorted(e.attempt for e in events)  # attempt 1 never after 2
    assert str(terminals[0].data["result"]).startswith("a2r")
    assert info.status == JobStatus.done and info.attempt == 2 and info.result == terminals[0].data["result"]
    text = hosts.logs[hung].read_text(errors="replace")
    assert "attempt 1 lost the job" in text and "publishes nothing more" in text
