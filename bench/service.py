"""Benchmark: the service runtime through its public HTTP/WebSocket API.

Starts real processes on 127.0.0.1 (a private redis-server on a free port, ``segue serve``, and for
the Redis run two ``segue worker`` processes), then measures:

* ``first_event_p50_ms`` / ``first_event_p95_ms``: from sending ``POST /v1/jobs`` to receiving the
  job's first worker event (``started``) over its WebSocket, warm database, embedded backend;
* ``first_solution_p50_ms``: the same to the first ``solution`` event;
* ``redis_first_event_p50_ms`` / ``redis_first_event_p95_ms``: the same through Redis + 2 workers;
* ``redis_jobs_per_s``: ``clip`` jobs completed per second through Redis with 2 workers;
* ``fanout_subscribers`` / ``events_lost``: one job streamed to 200 WebSocket subscribers at once;
  an event is lost when a subscriber misses a non-solution event or the final solution.

Prints one JSON object. Needs ``redis-server`` on PATH for the Redis figures (else they are null).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import websockets

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from motion.samples import sample_path  # noqa: E402

PLUGIN = "tests.workers.scripted_engine"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_http(url: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if httpx.get(url, timeout=1.0).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    raise RuntimeError(f"{url} did not answer within {timeout} s")


class Processes:
    def __init__(self) -> None:
        self.procs: list[subprocess.Popen[bytes]] = []

    def start(self, args: list[str], env: dict[str, str]) -> subprocess.Popen[bytes]:
        p = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
        self.procs.append(p)
        return p

    def stop(self) -> None:
        for p in self.procs:
            p.terminate()
        for p in self.procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()


def segue_env(data_dir: str) -> dict[str, str]:
    env = dict(os.environ)
    env["SEGUE_DATA_DIR"] = data_dir
    env["SEGUE_ENGINE_PLUGINS"] = PLUGIN
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return env


async def prepare(client: httpx.AsyncClient) -> str:
    """Upload the bundled walk, build a clips database, return its id once ready."""
    path = sample_path("walk")
    r = await client.post("/v1/clips", files={"file": (path.name, path.read_bytes())})
    r.raise_for_status()
    spec = {"kind": "clips", "clips": [{"bvh": path.name, "name": "walk"}], "fps": 30}
    r = await client.post("/v1/databases", json=spec)
    r.raise_for_status()
    db = r.json()["id"]
    for _ in range(600):
        info = (await client.get(f"/v1/databases/{db}")).json()
        if info["status"] == "ready":
            return str(db)
        if info["status"] == "failed":
            raise RuntimeError(f"database build failed: {info.get('error')}")
        await asyncio.sleep(0.05)
    raise RuntimeError("database build did not finish")


async def job_latency(client: httpx.AsyncClient, ws_base: str, db: str) -> tuple[float, float]:
    """(ms to the first worker event, ms to the first solution) of one clip job."""
    t0 = time.perf_counter()
    r = await client.post("/v1/jobs", json={"engine": "clip", "database": db, "clip": "walk", "end": 30})
    r.raise_for_status()
    job = r.json()["id"]
    first_event = first_solution = float("nan")
    async with websockets.connect(f"{ws_base}/v1/jobs/{job}/events?after=1") as ws:
        async for raw in ws:
            event = json.loads(raw)
            now_ms = (time.perf_counter() - t0) * 1e3
            if first_event != first_event:  # nan
                first_event = now_ms
            if event["type"] == "solution" and first_solution != first_solution:
                first_solution = now_ms
            if event["type"] in ("done", "failed", "cancelled"):
                break
    return first_event, first_solution


async def latencies(base: str, n: int) -> dict[str, float]:
    ws_base = base.replace("http://", "ws://")
    async with httpx.AsyncClient(base_url=base, timeout=60) as client:
        db = await prepare(client)
        for _ in range(3):  # warm the workers' database caches
            await job_latency(client, ws_base, db)
        samples = [await job_latency(client, ws_base, db) for _ in range(n)]
    ev = sorted(s[0] for s in samples)
    sol = sorted(s[1] for s in samples)
    return {
        "p50": statistics.median(ev),
        "p95": ev[min(len(ev) - 1, int(0.95 * len(ev)))],
        "solution_p50": statistics.median(sol),
    }


async def throughput(base: str, n_jobs: int) -> float:
    async with httpx.AsyncClient(base_url=base, timeout=120) as client:
        db = await prepare(client)
        t0 = time.perf_counter()
        jobs = []
        for _ in range(n_jobs):
            r = await client.post(
                "/v1/jobs", json={"engine": "clip", "database": db, "clip": "walk", "end": 30}
            )
            r.raise_for_status()
            jobs.append(r.json()["id"])
        pending = set(jobs)
        while pending:
            for job in list(pending):
                if (await client.get(f"/v1/jobs/{job}")).json()["status"] in ("done", "failed", "cancelled"):
                    pending.discard(job)
            await asyncio.sleep(0.02)
        return n_jobs / (time.perf_counter() - t0)


async def fanout(base: str, subscribers: int) -> dict[str, int]:
    ws_base = base.replace("http://", "ws://")
    async with httpx.AsyncClient(base_url=base, timeout=60) as client:
        db = await prepare(client)
        r = await client.post(
            "/v1/jobs", json={"engine": "scripted", "database": db, "steps": 30, "step_s": 0.05}
        )
        r.raise_for_status()
        job = r.json()["id"]

        async def subscribe() -> list[dict[str, Any]]:
            async with websockets.connect(f"{ws_base}/v1/jobs/{job}/events?after=0", open_timeout=30) as ws:
                return [json.loads(raw) async for raw in ws]

        received = await asyncio.gather(*(subscribe() for _ in range(subscribers)))
        everything = (await client.get(f"/v1/jobs/{job}/events", params={"after": 0})).json()
    expected_ids = {e["id"] for e in everything if e["type"] != "solution"}
    last_solution = max((e["id"] for e in everything if e["type"] == "solution"), default=None)
    if last_solution is not None:
        expected_ids.add(last_solution)
    lost = sum(len(expected_ids - {e["id"] for e in got}) for got in received)
    delivered = sum(len(got) for got in received)
    return {
        "subscribers": subscribers,
        "events_lost": lost,
        "events_delivered": delivered,
        "events_in_job": len(everything),
    }


def run_embedded(n: int, subscribers: int) -> dict[str, Any]:
    procs = Processes()
    data = tempfile.mkdtemp(prefix="segue-bench-")
    try:
        port = free_port()
        procs.start(
            [
                sys.executable,
                "-m",
                "service.cli",
                "serve",
                "--port",
                str(port),
                "--workers",
                "2",
                "--log-level",
                "warning",
            ],
            segue_env(data),
        )
        base = f"http://127.0.0.1:{port}"
        wait_http(f"{base}/healthz")
        lat = asyncio.run(latencies(base, n))
        fan = asyncio.run(fanout(base, subscribers))
        return {"lat": lat, "fan": fan}
    finally:
        procs.stop()
        shutil.rmtree(data, ignore_errors=True)


def run_redis(n: int, n_jobs: int) -> dict[str, Any] | None:
    if shutil.which("redis-server") is None:
        return None
    procs = Processes()
    data = tempfile.mkdtemp(prefix="segue-bench-")
    try:
        rport, port = free_port(), free_port()
        procs.start(
            ["redis-server", "--port", str(rport), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no"],
            dict(os.environ),
        )
        url = f"redis://127.0.0.1:{rport}/0"
        env = segue_env(data)
        time.sleep(0.3)
        procs.start(
            [
                sys.executable,
                "-m",
                "service.cli",
                "serve",
                "--port",
                str(port),
                "--redis",
                url,
                "--log-level",
                "warning",
            ],
            env,
        )
        for i in range(2):
            procs.start(
                [
                    sys.executable,
                    "-m",
                    "service.cli",
                    "worker",
                    "--redis",
                    url,
                    "--data",
                    data,
                    "--name",
                    f"bench-{i}",
                ],
                env,
            )
        base = f"http://127.0.0.1:{port}"
        wait_http(f"{base}/healthz")
        lat = asyncio.run(latencies(base, n))
        jobs_per_s = asyncio.run(throughput(base, n_jobs))
        return {"lat": lat, "jobs_per_s": jobs_per_s}
    finally:
        procs.stop()
        shutil.rmtree(data, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--latency-jobs", type=int, default=30)
    ap.add_argument("--throughput-jobs", type=int, default=100)
    ap.add_argument("--subscribers", type=int, default=200)
    args = ap.parse_args(argv)
    emb = run_embedded(args.latency_jobs, args.subscribers)
    red = run_redis(args.latency_jobs, args.throughput_jobs)
    out = {
        "first_event_p50_ms": round(emb["lat"]["p50"], 2),
        "first_event_p95_ms": round(emb["lat"]["p95"], 2),
        "first_solution_p50_ms": round(emb["lat"]["solution_p50"], 2),
        "redis_first_event_p50_ms": None if red is None else round(red["lat"]["p50"], 2),
        "redis_first_event_p95_ms": None if red is None else round(red["lat"]["p95"], 2),
        "redis_first_solution_p50_ms": None if red is None else round(red["lat"]["solution_p50"], 2),
        "redis_jobs_per_s": None if red is None else round(red["jobs_per_s"], 1),
        "fanout_subscribers": emb["fan"]["subscribers"],
        "events_lost": emb["fan"]["events_lost"],
        "fanout_events_delivered": emb["fan"]["events_delivered"],
    }
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
