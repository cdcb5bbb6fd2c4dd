"""Fair scheduling: does one principal's backlog delay another principal's next job?

Starts real processes on 127.0.0.1 (``segue serve`` with two tokens, and for ``redis`` a
``redis-server`` and two ``segue worker``s; the embedded backend runs two engine processes), builds
a ``graph`` database of the bundled walk for both principals, then:

1. ``alice`` submits ``--backlog`` graph jobs (``budget_s`` ``--budget``: each takes about that);
2. once her first jobs run, ``bob`` submits one job;
3. measured: how long bob's job waits for a worker (his submit → his ``started`` event), how many of
   alice's jobs started in between, and the median run time of alice's jobs (``started`` →
   terminal), so the wait reads in jobs: ``bob_wait_jobs`` = wait / median job time.

Fair means bob's job starts when the first worker frees up: ``bob_wait_jobs`` at most 1 and at most
one of alice's jobs started per worker in between. A FIFO queue makes him wait for her whole backlog
(``backlog`` x job time / workers). alice's remaining jobs are cancelled at the end. Prints one JSON
object per backend.

    python bench/fairness.py [--backend embedded,redis] [--backlog 256] [--budget 0.5]
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from faults import Topology, walk_graph

TOKENS = "alice:alice-token,bob:bob-token"
FINISHED = ("done", "failed", "cancelled")


def _client(url: str, token: str) -> httpx.Client:
    return httpx.Client(base_url=url, timeout=60, headers={"Authorization": f"Bearer {token}"})


def _seconds(text: str | None) -> float | None:
    return datetime.fromisoformat(text).timestamp() if text else None


def _run_time(http: httpx.Client, job: str) -> float | None:
    """A finished job's run time, seconds (its last ``started`` to its terminal event)."""
    events = http.get(f"/v1/jobs/{job}/events").json()
    starts = [e["time"] for e in events if e["type"] == "started"]
    ends = [e["time"] for e in events if e["type"] in FINISHED]
    return ends[-1] - starts[-1] if starts and ends else None


def fairness(backend: str, backlog: int = 256, budget: float = 0.5, workers: int = 2) -> dict[str, Any]:
    """One measurement (see the module docstring) on ``backend`` (``embedded`` or ``redis``)."""
    root = Path(tempfile.mkdtemp(prefix=f"segue-fairness-{backend}-"))
    top = Topology(root, "plain" if backend == "redis" else None, workers=workers, tokens=TOKENS)
    try:
        top.start()
        alice, bob = _client(top.url, "alice-token"), _client(top.url, "bob-token")
        db = walk_graph(alice)
        assert walk_graph(bob) == db  # the same bytes and spec: one database, held by both

        def job(k: int) -> dict[str, Any]:
            return {"engine": "graph", "database": db, "frames": 120 + k % 60, "budget_s": budget}

        mine = []
        for k in range(backlog):
            r = alice.post("/v1/jobs", json=job(k))
            r.raise_for_status()
            mine.append(r.json()["id"])
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # her backlog is being served
            if any(alice.get(f"/v1/jobs/{j}").json()["status"] != "queued" for j in mine[:workers]):
                break
            time.sleep(0.05)
        submitted = time.time()
        his = bob.post("/v1/jobs", json=job(7)).json()["id"]
        deadline = time.monotonic() + 900
        while time.monotonic() < deadline:
            status = bob.get(f"/v1/jobs/{his}").json()
            if status["status"] != "queued":
                break
            time.sleep(0.05)
        events = bob.get(f"/v1/jobs/{his}/events").json()
        started = next(e["time"] for e in events if e["type"] == "started")
        infos = alice.get("/v1/jobs", params={"limit": 1000}).json()
        between = [
            i
            for i in infos
            if i["id"] in set(mine)
            and (t := _seconds(i.get("started_at"))) is not None
            and submitted < t < started
        ]
        for j in mine:  # end her backlog
            alice.post(f"/v1/jobs/{j}/cancel")
        finished = [i["id"] for i in infos if i["id"] in set(mine) and i["status"] == "done"][:20]
        times = [t for t in (_run_time(alice, j) for j in finished) if t is not None]
        job_s = statistics.median(times) if times else None
        wait = started - submitted
        return {
            "backend": backend,
            "workers": workers,
            "backlog": backlog,
            "job_s_p50": round(job_s, 3) if job_s else None,
            "bob_wait_s": round(wait, 3),
            "bob_wait_jobs": round(wait / job_s, 2) if job_s else None,
            "alice_jobs_started_before_bob": len(between),
        }
    finally:
        top.stop()
        shutil.rmtree(root, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--backend", default="embedded,redis")
    ap.add_argument("--backlog", type=int, default=256)
    ap.add_argument("--budget", type=float, default=0.5)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    out = [fairness(b, args.backlog, args.budget, args.workers) for b in args.backend.split(",") if b]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
