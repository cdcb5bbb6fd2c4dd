"""Benchmark: the API process's memory and responsiveness under hostile inputs.

Starts a real ``segue serve`` (embedded workers, two principals ``alice`` and ``bob``) on a free
127.0.0.1 port with a fresh data directory, builds a rhythm database from a bundled sample, runs a
solo and a 20-dancer crowd job, measures the API process's idle RSS, then sends as alice:

* ``gzip_bvh``: a 1 MB gzip BVH holding 1.9M frames of a 21-joint body (~250 MB of text, under
  the 256 MB inflate cap) as a clip upload;
* ``midi_events``: an 8 MB MIDI file of 2.8M events, then two rhythm jobs dancing to it;
* ``midi_tempo``: a 36-byte MIDI whose tempo is 1 us per quarter note, then a job dancing to it;
* ``flac_hour``: an hour of 96 kHz stereo FLAC, then jobs dancing to it (1 and 10,000 dancers);
* ``crowd_json``: the crowd's result as ``?format=json&fps=1000``;
* ``characters``: six parallel ``GET .../result?character=<the 1.9M-frame clip>``;
* ``uploads``: eight parallel 60 MiB input-file uploads (``POST /v1/files``, each body streamed
  by the client in 1 MiB chunks, distinct bytes so none is a duplicate);

while bob submits a trivial job (then cancels it) every 0.5 s. Prints one JSON object: per step
its HTTP statuses, seconds and the API's peak RSS over idle; overall the peak RSS over idle
(goal <= 300 MB), the API's CPU seconds, and bob's submission latency (goal: max <= 1 s).

``--root DIR`` runs another checkout's code (e.g. main, for a before/after table); the server is
stopped when its RSS passes ``--rss-abort-mb`` (a guard for a shared machine), which the step then
reports. Needs nothing but this repository (inputs are generated in the temporary directory).
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PAGE = os.sysconf("SC_PAGE_SIZE")
TICKS = os.sysconf("SC_CLK_TCK")
TOKENS = {"alice": "alice-token-0123456789", "bob": "bob-token-0123456789"}


# -- inputs ---------------------------------------------------------------------------------------
def hostile_bvh(frames: int = 1_900_000) -> bytes:
    """A 21-joint humanoid (cm) standing still for ``frames`` frames, gzip-compressed: ~1 MB for
    1.9M frames (~250 MB of text, under the default 256 MB inflate cap)."""
    limbs = {  # first joint's offset from the hips, then each next joint's from its parent
        ("Spine", "Chest", "Neck", "Head"): ((0, 10, 0), (0, 15, 0)),
        ("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"): ((9, 0, 0), (0, -42, 0)),
        ("RightUpLeg", "RightLeg", "RightFoot", "RightToeBase"): ((-9, 0, 0), (0, -42, 0)),
        ("LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"): ((5, 45, 0), (15, 0, 0)),
        ("RightShoulder", "RightArm", "RightForeArm", "RightHand"): ((-5, 45, 0), (-15, 0, 0)),
    }
    lines = ["HIERARCHY", "ROOT Hips", "{", "  OFFSET 0 0 0"]
    lines.append("  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
    channels = 6
    for joints, (first, step) in limbs.items():
        for depth, joint in enumerate(joints, start=1):
            pad, off = "  " * depth, first if depth == 1 else step
            lines += [f"{pad}JOINT {joint}", f"{pad}{{", f"{pad}  OFFSET {off[0]} {off[1]} {off[2]}"]
            lines.append(f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation")
            channels += 3
        pad = "  " * (len(joints) + 1)
        lines += [f"{pad}End Site", f"{pad}{{", f"{pad}  OFFSET 0 5 0", f"{pad}}}"]
        lines += ["  " * depth + "}" for depth in range(len(joints), 0, -1)]
    lines += ["}", "MOTION", f"Frames: {frames}", "Frame Time: 0.0083333"]
    head = ("\n".join(lines) + "\n").encode()
    row = b"0 95 0 " + b"0 " * (channels - 4) + b"0\n"
    return gzip.compress(head, 9) + gzip.compress(row * frames, 9)


def hostile_midi(events: int = 2_800_000) -> bytes:
    """One track of ``events`` note events (running status), ~8 MB."""
    track = bytes([0x00, 0x90, 60, 100]) + bytes([0x00, 60, 0]) * (events - 1)
    track += bytes([0x00, 0xFF, 0x2F, 0x00])
    header = b"MThd" + (6).to_bytes(4, "big") + bytes([0, 0, 0, 1, 0, 96])
    return header + b"MTrk" + len(track).to_bytes(4, "big") + track


def tempo_midi() -> bytes:
    """36 bytes: tempo 1 us per quarter note, one quarter note per tick, end after 2^28 ticks."""
    track = bytes([0x00, 0xFF, 0x51, 3, 0, 0, 1, 0xFF, 0xFF, 0xFF, 0x7F, 0xFF, 0x2F, 0x00])
    header = b"MThd" + (6).to_bytes(4, "big") + bytes([0, 0, 0, 1, 0, 1])
    return header + b"MTrk" + len(track).to_bytes(4, "big") + track


def hour_flac(path: Path, seconds: int = 3600, rate: int = 96_000) -> bytes:
    """An hour of 96 kHz stereo FLAC: a quiet 2 Hz click (compresses to a few MB)."""
    import soundfile as sf

    block = np.zeros((rate, 2), dtype=np.int16)
    block[: rate // 100] = 300
    with sf.SoundFile(path, "w", samplerate=rate, channels=2, format="FLAC", subtype="PCM_16") as fh:
        for _ in range(seconds):
            fh.write(block)
    return path.read_bytes()


# -- the server ------------------------------------------------------------------------------------
def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def rss_bytes(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/statm", "rb") as fh:
            return int(fh.read().split()[1]) * PAGE
    except (OSError, IndexError, ValueError):
        return 0


def cpu_seconds(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            fields = fh.read().rsplit(b")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / TICKS
    except (OSError, IndexError, ValueError):
        return 0.0


class Sampler(threading.Thread):
    """The API process's RSS every 20 ms; kills the server past ``abort`` bytes."""

    def __init__(self, proc: subprocess.Popen[bytes], abort: int) -> None:
        super().__init__(daemon=True)
        self.proc, self.abort = proc, abort
        self.peak = 0
        self.aborted = False
        self._halt = threading.Event()

    def reset(self) -> None:
        self.peak = rss_bytes(self.proc.pid)

    def run(self) -> None:
        while not self._halt.wait(0.02):
            rss = rss_bytes(self.proc.pid)
            self.peak = max(self.peak, rss)
            if rss > self.abort and not self.aborted:
                self.aborted = True
                self.proc.kill()

    def stop(self) -> None:
        self._halt.set()


class Prober(threading.Thread):
    """bob submits a trivial job (and cancels it) every 0.5 s; records each POST's seconds."""

    def __init__(self, url: str, database: str) -> None:
        super().__init__(daemon=True)
        self.url, self.database = url, database
        self.latencies: list[float] = []
        self.errors: dict[str, int] = {}
        self._halt = threading.Event()

    def run(self) -> None:
        body = {
            "engine": "rhythm",
            "database": self.database,
            "music": {"bpm": 120, "duration_s": 2},
            "budget_s": 0.2,
        }
        with httpx.Client(base_url=self.url, headers=auth("bob"), timeout=300) as client:
            while not self._halt.wait(0.5):
                t0 = time.perf_counter()
                try:
                    r = client.post("/v1/jobs", json=body)
                except httpx.HTTPError as exc:
                    self.errors[type(exc).__name__] = self.errors.get(type(exc).__name__, 0) + 1
                    continue
                self.latencies.append(time.perf_counter() - t0)
                if r.status_code == 202:
                    client.post(f"/v1/jobs/{r.json()['id']}/cancel")
                else:
                    self.errors[str(r.status_code)] = self.errors.get(str(r.status_code), 0) + 1

    def stop(self) -> None:
        self._halt.set()


def auth(who: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {TOKENS[who]}"}


def wait_job(client: httpx.Client, job: str, timeout: float = 600) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        info = client.get(f"/v1/jobs/{job}").json()
        if info["status"] in ("done", "failed", "cancelled"):
            return dict(info)
        time.sleep(0.3)
    raise RuntimeError(f"job {job} did not end in {timeout} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--root", type=Path, default=ROOT, help="the checkout whose code runs")
    parser.add_argument("--rss-abort-mb", type=float, default=2500, help="stop the server past this RSS")
    parser.add_argument("--timeout", type=float, default=300, help="seconds per request")
    parser.add_argument("--only", help="comma-separated steps to run (default: all, in order)")
    args = parser.parse_args()
    out: dict[str, Any] = {"root": str(args.root), "steps": {}}
    with tempfile.TemporaryDirectory(prefix="segue-apimem-") as tmp:
        tmpdir = Path(tmp)
        t0 = time.perf_counter()
        inputs = {
            "bvh": hostile_bvh(),
            "midi": hostile_midi(),
            "tempo": tempo_midi(),
            "flac": hour_flac(tmpdir / "hour.flac"),
        }
        out["inputs"] = {k: len(v) for k, v in inputs.items()}
        out["inputs_generated_s"] = round(time.perf_counter() - t0, 1)
        port = free_port()
        env = os.environ | {
            "SEGUE_DATA_DIR": str(tmpdir / "data"),
            "SEGUE_API_TOKENS": ",".join(f"{who}:{tok}" for who, tok in TOKENS.items()),
            "SEGUE_WORKERS": "2",
            "PYTHONPATH": str(args.root),
        }
        env.pop("SEGUE_REDIS_URL", None)
        log = (tmpdir / "serve.log").open("wb")
        proc = subprocess.Popen(
            [sys.executable, "-m", "service.cli", "serve", "--port", str(port), "--no-warm",
             "--log-level", "warning"],
            cwd=args.root, env=env, stdout=log, stderr=subprocess.STDOUT,
        )  # fmt: skip
        url = f"http://127.0.0.1:{port}"
        try:
            run(url, proc, inputs, args, out)
        finally:
            proc.terminate()
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
            log.close()
            out["server_log_tail"] = (tmpdir / "serve.log").read_text(errors="replace")[-600:]
    print(json.dumps(out, indent=1))


def run(
    url: str, proc: subprocess.Popen[bytes], inputs: dict[str, bytes], args: Any, out: dict[str, Any]
) -> None:
    deadline = time.monotonic() + 180
    while True:
        try:
            if httpx.get(f"{url}/healthz", timeout=2).status_code == 200:
                break
        except httpx.HTTPError:
            pass
        if time.monotonic() > deadline or proc.poll() is not None:
            raise RuntimeError("segue serve did not start")
        time.sleep(0.3)
    alice = httpx.Client(base_url=url, headers=auth("alice"), timeout=args.timeout)
    bob = httpx.Client(base_url=url, headers=auth("bob"), timeout=args.timeout)
    spec = {"kind": "rhythm", "clips": [{"bvh": "sample:salsa-leader"}], "beats_per_movement": 4}
    db = alice.post("/v1/databases", json=spec).json()
    bob.post("/v1/databases", json=spec)
    if db.get("build_job"):
        wait_job(alice, db["build_job"])
    solo = alice.post(
        "/v1/jobs",
        json={
            "engine": "rhythm",
            "database": db["id"],
            "music": {"bpm": 120, "duration_s": 10},
            "budget_s": 1,
        },
    ).json()
    crowd = alice.post(
        "/v1/jobs",
        json={
            "engine": "rhythm",
            "database": db["id"],
            "music": {"bpm": 120, "duration_s": 20},
            "characters": 20,
            "budget_s": 1,
        },
    ).json()
    wait_job(alice, solo["id"])
    wait_job(alice, crowd["id"])
    alice.get(f"/v1/jobs/{solo['id']}/result")  # warm the download path
    time.sleep(2)
    samples = []
    for _ in range(10):
        samples.append(rss_bytes(proc.pid))
        time.sleep(0.1)
    idle = statistics.median(samples)
    out["idle_rss_mb"] = round(idle / 2**20, 1)
    sampler = Sampler(proc, int(args.rss_abort_mb * 2**20))
    sampler.start()
    prober = Prober(url, db["id"])
    prober.start()
    cpu0 = cpu_seconds(proc.pid)
    overall_peak = 0

    only = set(args.only.split(",")) if args.only else None

    def step(name: str, calls: list[Any]) -> None:
        nonlocal overall_peak
        if only is not None and name not in only:
            return
        if sampler.aborted or proc.poll() is not None:
            out["steps"][name] = {"skipped": "the server was stopped"}
            return
        sampler.reset()
        t = time.perf_counter()
        statuses: list[Any] = []
        for call in calls:
            try:
                statuses.append(call())
            except httpx.HTTPError as exc:
                statuses.append(type(exc).__name__)
        peak = sampler.peak
        overall_peak = max(overall_peak, peak)
        out["steps"][name] = {
            "status": statuses,
            "seconds": round(time.perf_counter() - t, 2),
            "peak_rss_over_idle_mb": round((peak - idle) / 2**20, 1),
            **({"aborted_over_mb": args.rss_abort_mb} if sampler.aborted else {}),
        }

    def upload(kind: str, name: str, data: bytes) -> Any:
        r = alice.post(f"/v1/{kind}", params={"name": name}, content=data)
        return r.status_code if r.status_code >= 300 else (r.status_code, r.json()["id"])

    def rhythm(music: dict[str, Any], characters: int = 1) -> Any:
        body = {"engine": "rhythm", "database": db["id"], "music": music, "characters": characters}
        r = alice.post("/v1/jobs", json={**body, "budget_s": 1})
        if r.status_code == 202:
            alice.post(f"/v1/jobs/{r.json()['id']}/cancel")
        return r.status_code

    ids: dict[str, str] = {}

    def keep(key: str, answer: Any) -> Any:
        if isinstance(answer, tuple):
            ids[key] = answer[1]
            return answer[0]
        return answer

    step("gzip_bvh", [lambda: keep("bvh", upload("clips", "long.bvh.gz", inputs["bvh"]))])
    step(
        "midi_events",
        [lambda: keep("midi", upload("files", "long.mid", inputs["midi"]))]
        + [lambda: rhythm({"midi": ids.get("midi", "long.mid")})] * 2,
    )
    step(
        "midi_tempo",
        [
            lambda: keep("tempo", upload("files", "fast.mid", inputs["tempo"])),
            lambda: rhythm({"midi": ids.get("tempo", "fast.mid")}),
        ],
    )
    step(
        "flac_hour",
        [
            lambda: keep("flac", upload("files", "hour.flac", inputs["flac"])),
            lambda: rhythm({"audio": ids.get("flac", "hour.flac"), "duration_s": 20}, 10_000),
            lambda: rhythm({"audio": ids.get("flac", "hour.flac")}),
        ],
    )
    step(
        "crowd_json",
        [
            lambda: alice.get(
                f"/v1/jobs/{crowd['id']}/result", params={"format": "json", "fps": 1000}
            ).status_code
        ],
    )

    def characters() -> Any:
        query = {"character": ids.get("bvh", "long.bvh.gz"), "format": "bvh"}
        with ThreadPoolExecutor(6) as pool:
            futures = [
                pool.submit(lambda: alice.get(f"/v1/jobs/{solo['id']}/result", params=query).status_code)
                for _ in range(6)
            ]
            return [f.result() for f in futures]

    step("characters", [characters])

    def uploads(count: int = 8, mib: int = 60) -> Any:
        def body(i: int) -> Any:
            block = bytes((i * 37 + j) % 256 for j in range(256)) * 4096  # 1 MiB
            for k in range(mib):
                yield block[k % 256 :] + block[: k % 256]

        def one(i: int) -> Any:
            r = alice.post("/v1/files", params={"name": f"big{i}.bin"}, content=body(i))
            return r.status_code

        with ThreadPoolExecutor(count) as pool:
            return sorted(pool.map(one, range(count)))

    step("uploads", [uploads])
    prober.stop()
    prober.join(10)
    sampler.stop()
    out["api_cpu_s"] = round(cpu_seconds(proc.pid) - cpu0, 1)
    out["peak_rss_over_idle_mb"] = round((overall_peak - idle) / 2**20, 1)
    lat = prober.latencies
    out["other_principal_submit_s"] = {
        "count": len(lat),
        "p50": round(statistics.median(lat), 3) if lat else None,
        "max": round(max(lat), 3) if lat else None,
        "errors": prober.errors,
    }
    out["goals"] = {
        "peak_rss_over_idle_le_300_mb": out["peak_rss_over_idle_mb"] <= 300 and not sampler.aborted,
        "other_submit_max_le_1_s": bool(lat) and max(lat) <= 1.0,
    }


if __name__ == "__main__":
    main()
