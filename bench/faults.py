"""Fault injection with real processes: does any job or event get lost, or run twice at once?

Every scenario starts its own processes on 127.0.0.1 (``segue serve``, ``segue worker``s and a
``redis-server`` on free ports, a fresh data directory), builds a ``graph`` database from the bundled
walk sample, submits ``--jobs`` graph jobs (``budget_s`` ``--budget``) with one WebSocket client per
job (reconnecting with ``after=<last id>`` whenever its socket drops), injects one fault while the
jobs run, and waits for every job to end. Scenarios:

* ``embedded_worker_kill``: SIGKILL of one engine process of ``segue serve`` (as the OOM killer);
* ``redis_worker_kill``: SIGKILL of one ``segue worker`` (its engine process exits with it);
* ``redis_restart_no_persistence``: SIGKILL of ``redis-server --save "" --appendonly no``, restarted
  empty one second later;
* ``redis_restart_aof``: the same with ``--appendonly yes --appendfsync everysec`` (restarted from
  its AOF);
* ``api_restart``: SIGKILL of ``segue serve`` (embedded; its engine processes exit with it),
  restarted on the same port and data directory;
* ``redis_worker_hang``: SIGSTOP of one ``segue worker`` and its engine process (a frozen host) for
  ``--hang`` seconds, past the reclaim time (its heartbeat expires, the other worker runs its job
  again as attempt 2), then SIGCONT: the resumed run must publish nothing (fenced attempts).

Per scenario: ``jobs_lost`` (jobs not ``done``), ``events_lost`` (gaps in the event ids the clients
received), ``duplicate_executions`` (a run of a job still publishing after a later run of the same
job started: result ids carry the attempt), ``duplicate_terminals`` (terminal events beyond one per
job, in each job's whole event log read back at the end), ``stale_events`` (events after a job's
last ``started`` that carry another attempt), ``reruns`` (runs after the first) and ``recovery_s``
(from the fault to the first event any client received afterwards). Prints one JSON object.

    python bench/faults.py [--jobs 4] [--budget 2] [--hang 8] [--only NAME,...]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
from websockets.sync.client import connect

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from motion.samples import sample_path  # noqa: E402

SEGUE = [sys.executable, "-m", "service.cli"]
JSON = {"Content-Type": "application/json"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_http(url: str, seconds: float = 60.0) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{url}/healthz", timeout=1).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.1)
    raise RuntimeError(f"{url} did not answer /healthz")


class Follower(threading.Thread):
    """One client of one job: WebSocket events, resuming with ``after=`` until the terminal event."""

    def __init__(self, ws_base: str, job: str, deadline: float) -> None:
        super().__init__(daemon=True)
        self.ws_base, self.job, self.deadline = ws_base, job, deadline
        self.events: list[tuple[float, dict[str, Any]]] = []

    @property
    def last(self) -> int:
        return self.events[-1][1]["id"] if self.events else 0

    def run(self) -> None:
        while time.monotonic() < self.deadline:
            try:
                with connect(
                    f"{self.ws_base}/v1/jobs/{self.job}/events?after={self.last}", open_timeout=5
                ) as ws:
                    for message in ws:
                        event = json.loads(message)
                        if event["id"] > self.last:
                            self.events.append((time.time(), event))
                        if event["type"] in ("done", "failed", "cancelled"):
                            return
            except Exception:
                time.sleep(0.2)

    def summary(self) -> dict[str, Any]:
        ids = [e["id"] for _, e in self.events]
        lost = (max(ids) - len(set(ids))) if ids else 0
        runs: list[int] = []
        duplicates = 0
        for _, e in self.events:
            if e["type"] == "started":
                runs.append(int(e["data"].get("attempt", len(runs) + 1)))
            elif e["type"] == "solution" and len(runs) > 1:
                rid = str(e["data"].get("result", ""))
                attempt = int(rid[1 : rid.index("r")]) if rid.startswith("a") else 1
                if attempt < runs[-1]:
                    duplicates = 1
        end = self.events[-1][1]["type"] if self.events else "none"
        return {"end": end, "events_lost": lost, "reruns": max(len(runs) - 1, 0), "duplicate": duplicates}


class Topology:
    """The processes of one scenario."""

    def __init__(
        self, root: Path, redis: str | None, workers: int, worker_env: dict[str, str] | None = None
    ) -> None:
        self.root, self.redis_mode, self.workers = root, redis, workers
        self.worker_env = worker_env or {}
        self.data = root / "data"
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.log = (root / "procs.log").open("wb")
        self.env = os.environ | {"PYTHONPATH": str(REPO), "SEGUE_DATA_DIR": str(self.data)}
        for var in ("SEGUE_API_TOKENS", "SEGUE_REDIS_URL", "SEGUE_ENGINE_PLUGINS"):
            self.env.pop(var, None)
        self.redis_port = free_port()
        self.redis_url = f"redis://127.0.0.1:{self.redis_port}/0"

    def start_redis(self) -> None:
        binary = shutil.which("redis-server")
        if binary is None:
            raise RuntimeError("redis-server is not installed")
        persist = ["--appendonly", "yes", "--appendfsync", "everysec"] if self.redis_mode == "aof" else [
            "--appendonly", "no"]  # fmt: skip
        self.procs["redis"] = subprocess.Popen(
            [binary, "--port", str(self.redis_port), "--bind", "127.0.0.1", "--save", "", *persist,
             "--dir", str(self.root)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.redis_port)) == 0:
                    return
            time.sleep(0.05)

    def start_api(self) -> None:
        cmd = [*SEGUE, "serve", "--port", str(self.port), "--workers", "2", "--log-level", "warning"]
        if self.redis_mode:
            cmd += ["--redis", self.redis_url]
        self.procs["api"] = subprocess.Popen(
            cmd, cwd=REPO, env=self.env, stdout=self.log, stderr=subprocess.STDOUT
        )
        wait_http(self.url)

    def start_worker(self, k: int) -> None:
        cmd = [*SEGUE, "worker", "--redis", self.redis_url, "--name", f"w{k}"]
        self.procs[f"w{k}"] = subprocess.Popen(
            cmd, cwd=REPO, env=self.env | self.worker_env, stdout=self.log, stderr=subprocess.STDOUT
        )

    def start(self) -> None:
        if self.redis_mode:
            self.start_redis()
        self.start_api()
        if self.redis_mode:
            for k in range(self.workers):
                self.start_worker(k)

    def stop(self) -> None:
        for name, proc in reversed(list(self.procs.items())):
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT if name != "redis" else signal.SIGTERM)
        for proc in self.procs.values():
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.log.close()


def engine_children(pid: int) -> list[int]:
    """PIDs of a process's engine children (``multiprocessing`` spawn children, not the tracker)."""
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids = (task / "children").read_text().split()
        except OSError:
            continue
        for kid in kids:
            try:
                cmd = Path(f"/proc/{kid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            if "resource_tracker" not in cmd:
                out.append(int(kid))
    return out


def job_log_facts(http: httpx.Client, job: str) -> dict[str, int]:
    """From a job's whole event log read back at the end: terminal events beyond the first, and
    events after the last ``started`` that carry another attempt."""
    events = http.get(f"/v1/jobs/{job}/events").json()
    terminals = sum(1 for e in events if e["type"] in ("done", "failed", "cancelled"))
    starts = [i for i, e in enumerate(events) if e["type"] == "started"]
    stale = 0
    if starts:
        attempt = events[starts[-1]].get("attempt")
        stale = sum(1 for e in events[starts[-1] :] if e.get("attempt") != attempt)
    return {"duplicate_terminals": max(terminals - 1, 0), "stale_events": stale}


def freeze(pid: int, sig: signal.Signals) -> list[int]:
    """Send ``sig`` (SIGSTOP, SIGCONT) to a worker and its engine processes; returns their pids."""
    pids = [pid, *engine_children(pid)]
    for p in pids:
        os.kill(p, sig)
    return pids


def scenario(name: str, n_jobs: int, budget: float, hang_s: float = 8.0) -> dict[str, Any]:
    redis_mode = {
        "redis_worker_kill": "plain",
        "redis_restart_no_persistence": "plain",
        "redis_restart_aof": "aof",
        "redis_worker_hang": "plain",
    }
    # a hung worker: its heartbeat expires after 2 s, entries idle 4 s are taken over
    hung = {"SEGUE_HEARTBEAT_TTL_S": "2", "SEGUE_RECLAIM_IDLE_S": "4"}
    worker_env = hung if name == "redis_worker_hang" else None
    root = Path(tempfile.mkdtemp(prefix=f"segue-faults-{name}-"))
    top = Topology(root, redis_mode.get(name), workers=2, worker_env=worker_env)
    try:
        top.start()
        http = httpx.Client(base_url=top.url, timeout=30)
        walk = sample_path("walk")
        clip = http.post("/v1/clips", files={"file": (walk.name, walk.read_bytes())}).json()
        db = http.post("/v1/databases", json={"kind": "graph", "clips": [{"clip": clip["id"]}]}).json()
        deadline = time.monotonic() + 120
        while http.get(f"/v1/databases/{db['id']}").json()["status"] != "ready":
            if time.monotonic() > deadline:
                raise RuntimeError("the database did not build")
            time.sleep(0.1)
        jobs = []
        for k in range(n_jobs):
            r = http.post(
                "/v1/jobs",
                json={"engine": "graph", "database": db["id"], "frames": 150 + k, "budget_s": budget},
            )
            r.raise_for_status()
            jobs.append(r.json()["id"])
        ws_base = top.url.replace("http", "ws")
        followers = [Follower(ws_base, j, time.monotonic() + 240) for j in jobs]
        for f in followers:
            f.start()
        time.sleep(min(1.0, budget / 2))
        fault_at = time.time()
        if name == "embedded_worker_kill":
            kids = engine_children(top.procs["api"].pid)
            os.kill(kids[0], signal.SIGKILL)
        elif name == "redis_worker_kill":
            top.procs["w0"].kill()
        elif name in ("redis_restart_no_persistence", "redis_restart_aof"):
            top.procs["redis"].kill()
            top.procs["redis"].wait()
            time.sleep(1.0)
            top.start_redis()
        elif name == "api_restart":
            top.procs["api"].kill()
            top.procs["api"].wait()
            top.start_api()
        elif name == "redis_worker_hang":
            frozen = freeze(top.procs["w0"].pid, signal.SIGSTOP)
            time.sleep(hang_s)
            for pid in frozen:
                os.kill(pid, signal.SIGCONT)
        for f in followers:
            f.join(240)
        if name == "redis_worker_hang":
            time.sleep(2.0)  # the resumed worker's buffered events, had they been published
        facts = [job_log_facts(http, j) for j in jobs]
        http.close()
        summaries = [f.summary() for f in followers]
        after = [t for f in followers for t, _ in f.events if t > fault_at]
        return {
            "jobs": n_jobs,
            "jobs_lost": sum(1 for s in summaries if s["end"] != "done"),
            "events_lost": sum(s["events_lost"] for s in summaries),
            "duplicate_executions": sum(s["duplicate"] for s in summaries),
            "duplicate_terminals": sum(f["duplicate_terminals"] for f in facts),
            "stale_events": sum(f["stale_events"] for f in facts),
            "reruns": sum(s["reruns"] for s in summaries),
            "recovery_s": round(min(after) - fault_at, 2) if after else None,
        }
    finally:
        top.stop()
        shutil.rmtree(root, ignore_errors=True)


SCENARIOS = (
    "embedded_worker_kill",
    "redis_worker_kill",
    "redis_restart_no_persistence",
    "redis_restart_aof",
    "api_restart",
    "redis_worker_hang",
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--jobs", type=int, default=4)
    ap.add_argument("--budget", type=float, default=2.0)
    ap.add_argument("--hang", type=float, default=8.0, help="seconds a hung worker stays stopped")
    ap.add_argument("--only", default=",".join(SCENARIOS))
    args = ap.parse_args()
    out = {name: scenario(name, args.jobs, args.budget, args.hang) for name in args.only.split(",") if name}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
