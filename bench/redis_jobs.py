"""Benchmark of the Redis runtime: throughput and latency of trivial ``clip`` jobs (prints JSON).

Starts a private ``redis-server`` on a free port and ``--workers`` worker processes, submits
``--jobs`` clip-excerpt jobs through :class:`workers.redis_backend.RedisBackend` and reports jobs/s
(first submit to last ``done``) and per-job latencies: submit → ``started`` (queue pickup, written by
the worker) and submit → ``done`` as seen by the API's event reader.

    python bench/redis_jobs.py --workers 2 --jobs 200
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

import numpy as np
import redis

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from engines.registry import parse_database_spec  # noqa: E402
from motion.samples import sample_path  # noqa: E402
from schemas import DatabaseInfo, DatabaseStatus, JobInfo, JobStatus  # noqa: E402
from schemas.databases import database_id  # noqa: E402
from schemas.jobs import JobKind  # noqa: E402
from workers.execute import EngineCache, execute_job  # noqa: E402
from workers.redis_backend import RedisBackend  # noqa: E402
from workers.redis_keys import RedisKeys  # noqa: E402
from workers.store import Store, now  # noqa: E402


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _database(store: Store) -> str:
    clip = store.put_clip("walk.bvh.gz", sample_path("walk").read_bytes())
    spec = parse_database_spec({"kind": "clips", "clips": [{"clip": clip.id, "name": "walk"}], "fps": 30})
    db_id = database_id(spec, [clip.id])
    info = DatabaseInfo(
        id=db_id, kind="clips", status=DatabaseStatus.queued, clips=["walk"], created_at=now()
    )
    store.put_database_info(info, spec.model_dump(mode="json"))
    execute_job(store, "b", "build", {"database": db_id}, lambda t, d: None, lambda: False, EngineCache())
    return db_id


async def _run(url: str, store: Store, db_id: str, jobs: int) -> dict[str, Any]:
    backend = RedisBackend(store, url)
    await backend.start()
    try:
        request = {"engine": "clip", "database": db_id, "clip": "walk", "start": 0, "end": 30}

        async def one() -> tuple[float, float, float]:
            job_id = uuid.uuid4().hex
            info = JobInfo(
                id=job_id,
                kind=JobKind.synth,
                engine="clip",
                database=db_id,
                status=JobStatus.queued,
                created_at=now(),
            )
            store.put_job(info, {"kind": "synth", "payload": {"request": request}})
            t0 = time.time()
            await backend.submit(info, "synth", {"request": request})
            started = done = 0.0
            async for event in backend.events(job_id):
                if event.type == "started":
                    started = event.time
                if event.type.terminal:
                    if event.type != "done":
                        raise RuntimeError(f"job {job_id} ended {event.type}: {event.data}")
                    done = time.time()
            return t0, started - t0, done - t0

        await asyncio.gather(*(one() for _ in range(8)))  # warm-up: every worker loads the database
        t_start = time.perf_counter()
        results = await asyncio.gather(*(one() for _ in range(jobs)))
        wall = time.perf_counter() - t_start
        pickup = np.array([r[1] for r in results]) * 1e3
        total = np.array([r[2] for r in results]) * 1e3
        # sequential latency: one job at a time (no queueing behind other jobs)
        seq = [await one() for _ in range(20)]
        seq_pickup = np.array([r[1] for r in seq]) * 1e3
        seq_total = np.array([r[2] for r in seq]) * 1e3
        return {
            "jobs": jobs,
            "wall_s": round(wall, 3),
            "jobs_per_s": round(jobs / wall, 1),
            "burst_submit_to_started_ms": {"p50": round(float(np.median(pickup)), 1)},
            "burst_submit_to_done_ms": {"p50": round(float(np.median(total)), 1)},
            "single_submit_to_started_ms": {
                "p50": round(float(np.median(seq_pickup)), 2),
                "p95": round(float(np.percentile(seq_pickup, 95)), 2),
            },
            "single_submit_to_done_ms": {
                "p50": round(float(np.median(seq_total)), 2),
                "p95": round(float(np.percentile(seq_total, 95)), 2),
            },
        }
    finally:
        await backend.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--jobs", type=int, default=200)
    args = parser.parse_args()
    binary = shutil.which("redis-server")
    if binary is None:
        raise SystemExit("redis-server is not installed")
    tmp = Path(tempfile.mkdtemp(prefix="segue-bench-"))
    port = _free_port()
    server = subprocess.Popen(
        [
            binary,
            "--port",
            str(port),
            "--bind",
            "127.0.0.1",
            "--save",
            "",
            "--appendonly",
            "no",
            "--dir",
            str(tmp),
        ],
        stdout=subprocess.DEVNULL,
    )
    url = f"redis://127.0.0.1:{port}/0"
    workers: list[subprocess.Popen[bytes]] = []
    try:
        client = redis.Redis.from_url(url)
        for _ in range(200):
            try:
                client.ping()
                break
            except redis.ConnectionError:
                time.sleep(0.02)
        store = Store(tmp / "data")
        db_id = _database(store)
        env = dict(os.environ, PYTHONPATH=str(REPO), SEGUE_LOG_LEVEL="WARNING")
        for i in range(args.workers):
            cmd = [sys.executable, "-m", "service.cli", "worker", "--redis", url, "--data", str(store.root)]
            workers.append(subprocess.Popen([*cmd, "--name", f"bench{i}"], env=env))
        keys = RedisKeys()
        while sum(bool(client.exists(keys.worker(f"bench{i}"))) for i in range(args.workers)) < args.workers:
            time.sleep(0.05)
        figures = asyncio.run(_run(url, store, db_id, args.jobs))
        print(json.dumps({"workers": args.workers, **figures}, indent=2))
    finally:
        for w in workers:
            w.send_signal(signal.SIGTERM)
        for w in workers:
            w.wait(timeout=30)
        server.terminate()
        server.wait(timeout=10)
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
