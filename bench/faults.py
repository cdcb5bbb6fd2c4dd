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

Two more run as separate hosts would: the API and the workers each with its own empty data
directory (a cache only), sharing only the ``redis-server`` and an S3-protocol server (``moto_server``
on a free port, ``SEGUE_STORE_URL=s3://<bucket>/segue``, ``AWS_ENDPOINT_URL``):

* ``s3_worker_kill``: workers without a shared directory; SIGKILL of one ``segue worker`` once its
  heartbeat names one of the jobs (that job runs again on the other host, from the store);
* ``s3_store_outage``: the object store stops answering for ``--hang`` seconds (SIGSTOP of
  ``moto_server``, then SIGCONT) while the jobs run. Not a kill and restart: moto keeps its objects in
  memory only (no persistence option in moto 5; its request recorder's replay would race the live
  writes), so a restarted moto is an empty store, which no real deployment has (MinIO and S3 keep
  their objects across a restart). What a restart looks like to Segue's clients is an outage: calls
  hang or fail, boto3 retries them (5 attempts), and what still fails after that is a
  ``StoreUnavailable`` (a 507 to API clients). This row shows that an outage shorter than the
  retries loses nothing; it cannot show a restart that loses objects.

Rows for the hardening of issue 40 (each printed with its own fields):

* ``build_worker_kill``: SIGKILL of the ``segue worker`` running a graph build (40 Bandai-Namco
  clips of ``../shared/data``, mirrored, all pairs: a few seconds, a progress event every ~0.3 s),
  three times in a row (``max_deliveries`` 3: the fourth delivery dead-letters it), ``--trials``
  times: how long each killed worker's engine process outlived it, whether the database record
  read ``failed`` while the build was still to be re-run, and the record's final status and error;
* ``redis_restart_no_persistence`` also reads every job's whole log back through a *new* API
  process: ``history_lost`` (event ids missing from 1..last), ``history_unterminated``;
* ``terminal_after_done``: clients polling each job's status and reading its events the moment it
  says finished: events lists without the terminal event;
* ``cache_disk_full``: S3 store, two workers, one with its data directory on a 32-KiB tmpfs
  (mounted for the row: root, or a user namespace), graph jobs: jobs done, failed, failed
  ``storage_full``, and the operator's log lines;
* ``upload_parse_killed``: a 100k-frame upload (gzip) whose parse a 300-MiB memory limit kills:
  the answer and the staged objects left in the store;
* ``s3_store_stall``: the API (embedded backend) over an S3 store (``moto_server``) that stops
  answering (SIGSTOP) for ``--stall`` seconds, ``SEGUE_STORE_TIMEOUT_S`` 2: per request made during
  the stall (``GET /v1/jobs/{id}``, ``GET /v1/jobs``, ``/readyz``, ``/healthz``) its status, code
  and seconds; after SIGCONT, the seconds until ``/readyz`` is 200 again and whether the job reads
  back (issue 40 item 9: the stall hung ``GET /v1/jobs/{id}`` over 8 s while ``/healthz`` said ok);
* ``fairness_embedded`` / ``fairness_redis``: ``bench/fairness.py`` (256 jobs of one principal, one of
  another: how long the other's waits, in jobs);
* ``slow_clients``: ``bench/slow_clients.py`` (4,100 connections of one principal from one address,
  each trickling a body byte every 12 s: another principal's request latency and failures).

Per scenario: ``jobs_lost`` (jobs not ``done``), ``events_lost`` (gaps in the event ids the clients
received), ``duplicate_executions`` (a run of a job still publishing after a later run of the same
job started: result ids carry the attempt), ``duplicate_terminals`` (terminal events beyond one per
job, in each job's whole event log read back at the end), ``stale_events`` (events after a job's
last ``started`` that carry another attempt), ``reruns`` (runs after the first) and ``recovery_s``
(from the fault to the first event any client received afterwards). Prints one JSON object.

    python bench/faults.py [--jobs 4] [--budget 2] [--hang 8] [--trials 3] [--stall 20] [--only NAME,...]

(the s3 rows need ``pip install -e '.[dev]'``: boto3 and ``moto[server]``)
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
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
from websockets.sync.client import connect

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from motion.samples import sample_path  # noqa: E402
from tests.processes import engine_children  # noqa: E402

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
        self,
        root: Path,
        redis: str | None,
        workers: int,
        worker_env: dict[str, str] | None = None,
        s3: bool = False,
        tokens: str | None = None,
    ) -> None:
        self.root, self.redis_mode, self.workers, self.s3 = root, redis, workers, s3
        self.worker_env = worker_env or {}
        self.worker_disks: dict[str, Path] = {}
        """A worker's own data directory when not ``root/<name>`` (a small file system: a full disk)."""
        self.data = root / "data"
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.log = (root / "procs.log").open("wb")
        self.env = os.environ | {"PYTHONPATH": str(REPO), "SEGUE_DATA_DIR": str(self.data)}
        for var in ("SEGUE_API_TOKENS", "SEGUE_REDIS_URL", "SEGUE_ENGINE_PLUGINS"):
            self.env.pop(var, None)
        if tokens:
            self.env["SEGUE_API_TOKENS"] = tokens
        self.redis_port = free_port()
        self.redis_url = f"redis://127.0.0.1:{self.redis_port}/0"
        self.s3_port = free_port()

    def own_disk(self, name: str) -> dict[str, str]:
        """A process's environment: on the S3 store, its own data directory (a host's disk)."""
        disk = self.worker_disks.get(name, self.root / name)
        return self.env | {"SEGUE_DATA_DIR": str(disk)} if self.s3 else self.env

    def start_s3(self) -> None:
        """``moto_server`` on a free port, a fresh bucket, the store settings in every process's env."""
        import boto3

        binary = shutil.which("moto_server")
        if binary is None:
            raise RuntimeError("moto_server is not installed (pip install 'moto[server]')")
        atomic = REPO / "tests" / "moto_atomic.py"  # each request atomic, as S3's are
        self.procs["s3"] = subprocess.Popen(
            [sys.executable, str(atomic), "-H", "127.0.0.1", "-p", str(self.s3_port)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        endpoint = f"http://127.0.0.1:{self.s3_port}"
        creds = {
            "AWS_ACCESS_KEY_ID": "bench",
            "AWS_SECRET_ACCESS_KEY": "bench",
            "AWS_DEFAULT_REGION": "us-east-1",
        }
        self.env |= creds | {"AWS_ENDPOINT_URL": endpoint, "SEGUE_STORE_URL": "s3://segue-faults/segue"}
        deadline = time.monotonic() + 60
        while True:
            try:
                httpx.get(endpoint, timeout=1)
                break
            except httpx.TransportError:
                if time.monotonic() > deadline:
                    raise RuntimeError("moto_server did not start") from None
                time.sleep(0.1)
        boto3.client(
            "s3",
            endpoint_url=endpoint,
            aws_access_key_id="bench",
            aws_secret_access_key="bench",
            region_name="us-east-1",
        ).create_bucket(Bucket="segue-faults")

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
            cmd, cwd=REPO, env=self.own_disk("api"), stdout=self.log, stderr=subprocess.STDOUT
        )
        wait_http(self.url)

    def start_worker(self, k: int) -> None:
        cmd = [*SEGUE, "worker", "--redis", self.redis_url, "--name", f"w{k}", "--no-warm"]
        self.procs[f"w{k}"] = subprocess.Popen(
            cmd,
            cwd=REPO,
            env=self.own_disk(f"w{k}") | self.worker_env,
            stdout=self.log,
            stderr=subprocess.STDOUT,
        )

    def start(self) -> None:
        if self.s3:
            self.start_s3()
        if self.redis_mode:
            self.start_redis()
        self.start_api()
        if self.redis_mode:
            for k in range(self.workers):
                self.start_worker(k)

    def stop(self) -> None:
        for name, proc in reversed(list(self.procs.items())):
            if proc.poll() is None:
                if name == "s3":
                    os.kill(proc.pid, signal.SIGCONT)
                proc.send_signal(signal.SIGINT if name != "redis" else signal.SIGTERM)
        for proc in self.procs.values():
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.log.close()


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


def wait_running(redis_url: str, worker: str, jobs: set[str], seconds: float = 60.0) -> None:
    """Wait until ``worker``'s heartbeat names one of ``jobs`` (its run started)."""
    import redis

    from workers.redis_keys import RedisKeys

    client = redis.Redis.from_url(redis_url, decode_responses=True)
    key = RedisKeys().worker(worker)
    deadline = time.monotonic() + seconds
    try:
        while time.monotonic() < deadline:
            raw = client.get(key)
            if raw and json.loads(raw).get("job") in jobs:
                return
            time.sleep(0.01)
    finally:
        client.close()
    raise RuntimeError(f"{worker} ran none of the jobs within {seconds} s")


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
        "s3_worker_kill": "plain",
        "s3_store_outage": "plain",
    }
    # a hung worker: its heartbeat expires after 2 s, entries idle 4 s are taken over
    hung = {"SEGUE_HEARTBEAT_TTL_S": "2", "SEGUE_RECLAIM_IDLE_S": "4"}
    worker_env = hung if name == "redis_worker_hang" else None
    root = Path(tempfile.mkdtemp(prefix=f"segue-faults-{name}-"))
    top = Topology(root, redis_mode.get(name), workers=2, worker_env=worker_env, s3=name.startswith("s3_"))
    try:
        top.start()
        http = httpx.Client(base_url=top.url, timeout=30)
        db_id = walk_graph(http)
        jobs = []
        for k in range(n_jobs):
            r = http.post(
                "/v1/jobs",
                json={"engine": "graph", "database": db_id, "frames": 150 + k, "budget_s": budget},
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
        elif name == "s3_worker_kill":
            wait_running(top.redis_url, "w0", set(jobs))  # a worker with a job of its own
            fault_at = time.time()
            top.procs["w0"].kill()
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
        elif name == "s3_store_outage":
            os.kill(top.procs["s3"].pid, signal.SIGSTOP)
            time.sleep(hang_s)
            os.kill(top.procs["s3"].pid, signal.SIGCONT)
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
        history = history_read_back(top, jobs) if name.startswith("redis_restart") else {}
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
            **history,
        }
    finally:
        top.stop()
        shutil.rmtree(root, ignore_errors=True)


def worker_of(redis_url: str, job: str, dead: set[str] | frozenset[str] = frozenset()) -> str | None:
    """The worker whose heartbeat names ``job`` (None when none does), not one of ``dead``."""
    import redis

    from workers.redis_keys import RedisKeys

    keys = RedisKeys()
    client = redis.Redis.from_url(redis_url, decode_responses=True)
    try:
        for key in client.scan_iter(match=keys.worker_pattern):
            raw = client.get(key)
            name = str(key)[len(keys.worker("")) :]
            if raw and json.loads(raw).get("job") == job and name not in dead:
                return name
    finally:
        client.close()
    return None


def bandai_clips(n: int) -> list[Path]:
    """The first ``n`` Bandai-Namco dataset-1 files (a graph build of seconds, not milliseconds)."""
    files = sorted((REPO.parent / "shared" / "data" / "bandai-namco" / "dataset-1").glob("*.bvh"))
    if len(files) < n:
        raise RuntimeError("the build-kill row needs ../shared/data/bandai-namco/dataset-1")
    return files[:n]


def alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie counts as gone)."""
    try:
        return "Z" not in Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False


def build_worker_kill(trials: int = 3, kills: int = 3) -> dict[str, Any]:
    """:func:`build_kill_trial` ``trials`` times (whether an orphan writes depends on where the
    kill lands: the figures are over all trials)."""
    runs = [build_kill_trial(kills) for _ in range(trials)]
    return {
        "trials": trials,
        "kills": [r["kills"] for r in runs],
        "orphan_alive_s_max": max(max(r["orphan_alive_s"], default=0.0) for r in runs),
        "trials_failed_before_the_end": sum(r["failed_before_the_end"] for r in runs),
        "failed_before_the_end_s_max": max(r["failed_before_the_end_s"] for r in runs),
        "final": [f"{r['final_status']}: {r['final_error']}" for r in runs],
    }


def build_kill_trial(kills: int = 3) -> dict[str, Any]:
    """SIGKILL of the ``segue worker`` running a graph build, ``kills`` times in a row (a new
    worker started after each): how long each killed worker's engine process outlives it, whether
    the database record reads ``failed`` while the build is re-run, and the record's final error
    (with ``max_deliveries`` 3, three kills dead-letter the build)."""
    root = Path(tempfile.mkdtemp(prefix="segue-faults-build-"))
    fast = {"SEGUE_HEARTBEAT_TTL_S": "2"}
    top = Topology(root, "plain", workers=2, worker_env=fast)
    records: list[tuple[float, str, str | None]] = []
    stop = threading.Event()
    try:
        top.start()
        http = httpx.Client(base_url=top.url, timeout=30)
        ids = []
        for path in bandai_clips(40):
            r = http.post("/v1/clips", files={"file": (path.name, path.read_bytes())})
            r.raise_for_status()
            ids.append(r.json()["id"])
        # about 4 s of build on the 2-core machine, a progress event every ~0.3 s (as real builds)
        spec = {
            "kind": "graph",
            "clips": [{"clip": i} for i in ids],
            "mirror": True,
            "candidates": "all_pairs",
        }
        db = http.post("/v1/databases", json=spec).json()
        job = db["build_job"]

        def watch() -> None:
            poll = httpx.Client(base_url=top.url, timeout=30)
            while not stop.is_set():
                info = poll.get(f"/v1/databases/{db['id']}").json()
                records.append((time.time(), info["status"], info.get("error")))
                time.sleep(0.02)
            poll.close()

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        orphan_s: list[float] = []
        killed: set[str] = set()
        next_worker = top.workers
        for _ in range(kills):
            deadline = time.monotonic() + 120
            name = None
            while name is None and time.monotonic() < deadline:
                name = worker_of(top.redis_url, job, killed)
                time.sleep(0.01)
            if name is None:
                break
            time.sleep(0.5)  # into the build (clips parsed, the graph being built)
            proc = top.procs[name]
            children = engine_children(proc.pid)
            killed_at = time.monotonic()
            proc.kill()
            proc.wait()
            killed.add(name)
            while any(alive(c) for c in children) and time.monotonic() - killed_at < 30:
                time.sleep(0.005)
            orphan_s.append(round(time.monotonic() - killed_at, 3))
            print(f"killed {name} (engine processes {children})", file=sys.stderr)
            top.start_worker(next_worker)
            next_worker += 1
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            info = http.get(f"/v1/jobs/{job}").json()
            if info["status"] in ("done", "failed", "cancelled"):
                break
            time.sleep(0.1)
        time.sleep(1.0)
        stop.set()
        watcher.join(10)
        end = http.get(f"/v1/jobs/{job}").json()
        final = http.get(f"/v1/databases/{db['id']}").json()
        http.close()
        ended = datetime_s(end.get("finished_at"))
        transient = [r for r in records if r[1] == "failed" and (ended is None or r[0] < ended - 0.05)]
        return {
            "kills": len(orphan_s),
            "orphan_alive_s": orphan_s,
            "job_status": end["status"],
            "final_status": final["status"],
            "final_error": final.get("error"),
            "failed_before_the_end": len(transient) > 0,
            "failed_before_the_end_s": round(transient[-1][0] - transient[0][0], 2) if transient else 0.0,
            "errors_seen": sorted({str(r[2]) for r in records if r[2]}),
        }
    finally:
        stop.set()
        top.stop()
        shutil.rmtree(root, ignore_errors=True)


def datetime_s(text: str | None) -> float | None:
    """An ISO time as Unix seconds (None stays None)."""
    from datetime import datetime

    return datetime.fromisoformat(text).timestamp() if text else None


def history_read_back(top: Topology, jobs: list[str]) -> dict[str, int]:
    """Each job's whole event log as a *new* API process reads it (from Redis and the store,
    nothing in memory): event ids missing from 1..last, and jobs whose log lacks its terminal event."""
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    cmd = [*SEGUE, "serve", "--port", str(port), "--workers", "1", "--log-level", "warning"]
    if top.redis_mode:
        cmd += ["--redis", top.redis_url]
    proc = subprocess.Popen(cmd, cwd=REPO, env=top.own_disk("api2"), stdout=top.log, stderr=subprocess.STDOUT)
    try:
        wait_http(url)
        missing = unterminated = 0
        with httpx.Client(base_url=url, timeout=30) as http:
            for job in jobs:
                events = http.get(f"/v1/jobs/{job}/events").json()
                ids = [e["id"] for e in events]
                last = max(ids) if ids else 0
                missing += last - len(set(ids))
                unterminated += not events or events[-1]["type"] not in ("done", "failed", "cancelled")
        return {"history_lost": missing, "history_unterminated": unterminated}
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()


def terminal_after_done(n_jobs: int = 24, budget: float = 0.5) -> dict[str, Any]:
    """Right after a job's status reads ``done``: does ``GET /events`` hold the terminal event?
    ``n_jobs`` short graph jobs on 2 workers, one client per job that reads its events once (so the
    API follows the job), then polls its status as fast as it can and reads the events the moment
    it reads a finished status."""
    root = Path(tempfile.mkdtemp(prefix="segue-faults-terminal-"))
    top = Topology(root, "plain", workers=2)
    try:
        top.start()
        http = httpx.Client(base_url=top.url, timeout=30)
        db = walk_graph(http)
        jobs = [
            http.post(
                "/v1/jobs",
                json={"engine": "graph", "database": db, "frames": 120 + k, "budget_s": budget},
            ).json()["id"]
            for k in range(n_jobs)
        ]
        lacking: list[int] = []

        def poll(job: str) -> None:
            with httpx.Client(base_url=top.url, timeout=30) as client:
                client.get(f"/v1/jobs/{job}/events")  # the API follows the job from now on
                deadline = time.monotonic() + 240
                while time.monotonic() < deadline:
                    if client.get(f"/v1/jobs/{job}").json()["status"] in ("done", "failed", "cancelled"):
                        events = client.get(f"/v1/jobs/{job}/events").json()
                        if not events or events[-1]["type"] not in ("done", "failed", "cancelled"):
                            lacking.append(1)
                        return

        threads = [threading.Thread(target=poll, args=(j,), daemon=True) for j in jobs]
        for t in threads:
            t.start()
        for t in threads:
            t.join(300)
        http.close()
        return {"jobs": n_jobs, "events_without_terminal_after_done": len(lacking)}
    finally:
        top.stop()
        shutil.rmtree(root, ignore_errors=True)


def walk_graph(http: httpx.Client) -> str:
    """A ready graph database of the bundled walk (its id)."""
    walk = sample_path("walk")
    clip = http.post("/v1/clips", files={"file": (walk.name, walk.read_bytes())}).json()
    db = http.post("/v1/databases", json={"kind": "graph", "clips": [{"clip": clip["id"]}]}).json()
    deadline = time.monotonic() + 120
    while http.get(f"/v1/databases/{db['id']}").json()["status"] != "ready":
        if time.monotonic() > deadline:
            raise RuntimeError("the database did not build")
        time.sleep(0.1)
    return str(db["id"])


def small_disk(path: Path, size_kib: int) -> None:
    """Mount a ``size_kib``-KiB tmpfs on ``path`` (root, or a user namespace; RuntimeError else)."""
    path.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size_kib}k", "tmpfs", str(path)], capture_output=True
    )
    if done.returncode != 0:
        raise RuntimeError(f"cannot mount a small disk: {done.stderr.decode().strip()}")


def cache_disk_full(n_jobs: int = 4, budget: float = 1.0) -> dict[str, Any]:
    """One worker's cache disk is full (a 32-KiB tmpfs, smaller than the database): S3 store, two
    workers on their own disks, ``n_jobs`` graph jobs. Counts jobs that failed, and how
    (``storage_full`` blames the user's data), and the jobs done."""
    root = Path(tempfile.mkdtemp(prefix="segue-faults-cachefull-"))
    top = Topology(root, "plain", workers=2, s3=True)
    top.worker_disks["w0"] = root / "w0-small"
    small_disk(top.worker_disks["w0"], 32)
    try:
        top.start()
        http = httpx.Client(base_url=top.url, timeout=30)
        db = walk_graph(http)
        jobs = [
            http.post(
                "/v1/jobs", json={"engine": "graph", "database": db, "frames": 150 + k, "budget_s": budget}
            ).json()["id"]
            for k in range(n_jobs)
        ]
        ends = []
        for job in jobs:
            deadline = time.monotonic() + 240
            while time.monotonic() < deadline:
                info = http.get(f"/v1/jobs/{job}").json()
                if info["status"] in ("done", "failed", "cancelled"):
                    break
                time.sleep(0.1)
            events = http.get(f"/v1/jobs/{job}/events").json()
            ends.append(events[-1] if events else {"type": "none", "data": {}})
        http.close()
        codes = [str((e["data"].get("error") or {}).get("code")) for e in ends if e["type"] == "failed"]
        log = (root / "procs.log").read_bytes().decode(errors="replace")
        return {
            "jobs": n_jobs,
            "done": sum(1 for e in ends if e["type"] == "done"),
            "failed": len(codes),
            "failed_storage_full": codes.count("storage_full"),
            "operator_log_lines": sum(1 for line in log.splitlines() if "cache" in line and "full" in line),
        }
    finally:
        top.stop()
        subprocess.run(["umount", str(root / "w0-small")], capture_output=True)
        shutil.rmtree(root, ignore_errors=True)


def tiled_walk(frames: int) -> bytes:
    """The bundled walk's frames repeated to ``frames`` frames, as gzip BVH text (a large upload
    that compresses well: what a worker, not the API, parses)."""
    import gzip
    import io
    from dataclasses import replace

    import numpy as np

    from motion import parse_bvh, write_bvh

    walk = parse_bvh(sample_path("walk").read_bytes())
    reps = -(-frames // walk.num_frames)
    rotations = np.concatenate([walk.rotations] * reps)[:frames]
    roots = np.concatenate([walk.root_positions] * reps)[:frames]
    buf = io.StringIO()
    write_bvh(replace(walk, rotations=rotations, root_positions=roots), buf)
    return gzip.compress(buf.getvalue().encode(), compresslevel=6)


def upload_parse_killed(frames: int = 100_000, memory_mb: int = 300) -> dict[str, Any]:
    """A large upload whose parse its worker's supervisor kills (``SEGUE_MAX_JOB_MEMORY_MB``
    ``memory_mb``: the parse of ``frames`` frames needs more): the answer, and the staged objects
    left in the store afterwards (embedded backend, local store)."""
    root = Path(tempfile.mkdtemp(prefix="segue-faults-staged-"))
    top = Topology(root, None, workers=1)
    top.env["SEGUE_MAX_JOB_MEMORY_MB"] = str(memory_mb)
    try:
        top.start()
        data = tiled_walk(frames)
        with httpx.Client(base_url=top.url, timeout=300) as http:
            r = http.post("/v1/clips", files={"file": ("long-walk.bvh.gz", data)})
        time.sleep(1.0)  # whatever the backend removes after answering
        staged = (
            sorted(p.name for p in (top.data / "staged").glob("*")) if (top.data / "staged").is_dir() else []
        )
        return {
            "upload_mb": round(len(data) / 2**20, 2),
            "frames": frames,
            "status": r.status_code,
            "code": (r.json().get("error") or {}).get("code") if r.status_code >= 400 else None,
            "staged_objects_left": len(staged),
        }
    finally:
        top.stop()
        shutil.rmtree(root, ignore_errors=True)


def s3_store_stall(stall_s: float = 20.0, timeout_s: float = 2.0) -> dict[str, Any]:
    """The object store stalls (SIGSTOP of ``moto_server``) under an embedded API with
    ``SEGUE_STORE_TIMEOUT_S`` ``timeout_s``: what requests made during the stall get, and how soon
    after SIGCONT the API is ready again."""
    root = Path(tempfile.mkdtemp(prefix="segue-faults-stall-"))
    top = Topology(root, None, workers=1, s3=True)
    top.env["SEGUE_STORE_TIMEOUT_S"] = str(timeout_s)
    out: dict[str, Any] = {"stall_s": stall_s, "store_timeout_s": timeout_s}
    try:
        top.start()
        http = httpx.Client(base_url=top.url, timeout=120)
        db = walk_graph(http)
        job = http.post("/v1/jobs", json={"engine": "graph", "database": db, "frames": 60, "budget_s": 0.5})
        job_id = job.json()["id"]
        deadline = time.monotonic() + 120
        while http.get(f"/v1/jobs/{job_id}").json()["status"] not in ("done", "failed", "cancelled"):
            if time.monotonic() > deadline:
                raise RuntimeError("the job did not end")
            time.sleep(0.2)

        def probe(path: str) -> dict[str, Any]:
            t0 = time.perf_counter()
            try:
                r = http.get(path)
            except httpx.HTTPError as exc:
                return {"status": type(exc).__name__, "s": round(time.perf_counter() - t0, 2)}
            code = (r.json().get("error") or {}).get("code") if r.status_code >= 400 and r.content else None
            return {"status": r.status_code, "code": code, "s": round(time.perf_counter() - t0, 2)}

        os.kill(top.procs["s3"].pid, signal.SIGSTOP)
        resume = threading.Timer(stall_s, os.kill, (top.procs["s3"].pid, signal.SIGCONT))
        resume.start()  # SIGCONT after stall_s whatever the probes wait for (a hanging API too)
        try:
            paths = {
                "job": f"/v1/jobs/{job_id}",
                "jobs": "/v1/jobs",
                "readyz": "/readyz",
                "healthz": "/healthz",
            }
            with ThreadPoolExecutor(len(paths)) as pool:
                during = dict(zip(paths, pool.map(probe, paths.values()), strict=True))
            out["during_stall"] = during
            resume.join()
        finally:
            resume.cancel()
            os.kill(top.procs["s3"].pid, signal.SIGCONT)
        resumed = time.monotonic()
        while http.get("/readyz").status_code != 200 and time.monotonic() - resumed < 120:
            time.sleep(0.1)
        out["ready_again_s"] = round(time.monotonic() - resumed, 2)
        out["job_after"] = probe(f"/v1/jobs/{job_id}")
        http.close()
        return out
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
    "s3_worker_kill",
    "s3_store_outage",
    "build_worker_kill",
    "terminal_after_done",
    "cache_disk_full",
    "upload_parse_killed",
    "s3_store_stall",
    "fairness_embedded",
    "fairness_redis",
    "slow_clients",
)


def run_one(name: str, args: argparse.Namespace) -> dict[str, Any]:
    """One row of the table."""
    if name == "build_worker_kill":
        return build_worker_kill(args.trials)
    if name == "terminal_after_done":
        return terminal_after_done()
    if name == "cache_disk_full":
        return cache_disk_full(args.jobs)
    if name == "upload_parse_killed":
        return upload_parse_killed()
    if name == "s3_store_stall":
        return s3_store_stall(args.stall)
    if name.startswith("fairness_"):
        from fairness import fairness  # bench/fairness.py

        return fairness(name.removeprefix("fairness_"))
    if name == "slow_clients":
        from slow_clients import slow_clients  # bench/slow_clients.py

        return slow_clients(connections=4100)
    return scenario(name, args.jobs, args.budget, args.hang)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--jobs", type=int, default=4)
    ap.add_argument("--budget", type=float, default=2.0)
    ap.add_argument("--hang", type=float, default=8.0, help="seconds a hung worker stays stopped")
    ap.add_argument("--trials", type=int, default=3, help="build_worker_kill: tries of the kills")
    ap.add_argument("--stall", type=float, default=20.0, help="s3_store_stall: seconds the store stalls")
    ap.add_argument("--only", default=",".join(SCENARIOS))
    args = ap.parse_args()
    out = {name: run_one(name, args) for name in args.only.split(",") if name}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
