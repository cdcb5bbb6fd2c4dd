"""Slow clients: does one token holder's trickle of connections lock the other principals out?

Starts ``segue serve`` on 127.0.0.1 with two tokens (``alice``, ``bob``; embedded backend), then:

1. the attacker (a separate process at nice 10, asyncio, the open-files soft limit raised to fit) holds
   ``--connections`` connections of ``bob`` from ``--addresses`` client addresses (127.0.0.2,
   127.0.0.3, ...): each sends the headers of a clip upload announcing a 1-MB body, then one body
   byte every ``--trickle`` seconds; a connection the server answers or closes is opened again
   after ``--reopen`` seconds, or the answer's ``Retry-After`` when longer (as HTTP clients do;
   ``--flood``: after ``--reopen`` whatever the answer says). ``--token none`` sends no token (an
   unauthenticated trickle);
2. once the attacker has opened them all (or ``--ramp`` seconds passed), ``alice`` (from
   127.0.0.1) sends ``GET /v1/clips`` on a new connection every ``--interval`` seconds for
   ``--seconds`` seconds; each answer's latency (connect to last byte) is one sample;
3. measured: alice's latency p50/p99/max and her failed requests (anything but 200, or no
   answer within 30 s), the attacker's connections open (sampled each second: mean, max) and
   the answers its connections got (by status, ``closed`` for a close without an answer).

``alice_before`` is the same measurement with no attacker (the machine's baseline). Prints one JSON
object.

    python bench/slow_clients.py [--connections 4000] [--addresses 1] [--seconds 60]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import os
import resource
import shutil
import statistics
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from faults import Topology

TOKENS = "alice:alice-token,bob:bob-token"
BODY_BYTES = 1_000_000


def raise_open_files(wanted: int) -> int:
    """The soft open-files limit raised towards ``wanted`` (at most the hard limit), as
    ``service/server.py`` does for the server; returns the limit now in force."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
    if target > soft:
        resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
        soft = target
    return soft


async def _slot(
    port: int, source: str, token: str | None, trickle: float, reopen: float, stats: dict[str, Any]
) -> None:
    """One attacker connection, reopened whenever the server answers or closes it."""
    auth = f"Authorization: Bearer {token}\r\n" if token else ""
    head = (
        f"POST /v1/clips?name=slow.bvh HTTP/1.1\r\nHost: 127.0.0.1\r\n{auth}"
        f"Content-Type: application/octet-stream\r\nContent-Length: {BODY_BYTES}\r\n\r\n"
    ).encode()
    while not stats["stop"]:
        writer = None
        try:
            reader, writer = await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))
            stats["open"] += 1
            stats["opened"] += 1
            try:
                writer.write(head)
                answer = b""
                while not stats["stop"]:
                    try:
                        answer = await asyncio.wait_for(reader.read(4096), trickle)
                        break  # an answer or EOF: the server is done with this connection
                    except TimeoutError:
                        writer.write(b"x")
                        await writer.drain()
                status = answer.split(b" ", 2)[1].decode() if answer.startswith(b"HTTP/") else "closed"
                if not stats["stop"]:
                    stats["answers"][status] += 1
                wait = max(reopen, retry_after(answer)) if stats["honour"] else reopen
            finally:
                stats["open"] -= 1
        except OSError as exc:
            stats["answers"][f"error:{type(exc).__name__}"] += 1
            wait = reopen
        finally:
            if writer is not None:
                writer.close()
        await asyncio.sleep(wait)


def retry_after(answer: bytes) -> float:
    """The ``Retry-After`` seconds of a response's head (0 without one)."""
    for line in answer.split(b"\r\n\r\n", 1)[0].split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"retry-after" and value.strip().isdigit():
            return float(value.strip())
    return 0.0


async def _attack(
    port: int, connections: int, addresses: int, token: str | None, trickle: float, reopen: float,
    ramp: float, seconds: float, honour: bool, out: Any, ready: Any,
) -> None:  # fmt: skip
    stats: dict[str, Any] = {"stop": False, "open": 0, "opened": 0, "answers": Counter(), "honour": honour}
    sources = [f"127.0.0.{2 + k}" for k in range(addresses)]
    tasks = []
    pace = ramp / connections
    for k in range(connections):
        tasks.append(asyncio.create_task(_slot(port, sources[k % addresses], token, trickle, reopen, stats)))
        await asyncio.sleep(pace)
    ready.set()
    stats["answers"].clear()  # count what happens while alice is measured
    stats["opened"] = 0
    samples = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        samples.append(stats["open"])
        await asyncio.sleep(1.0)
    stats["stop"] = True
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    out.put(
        {
            "attacker_open_mean": round(statistics.fmean(samples), 1) if samples else 0,
            "attacker_open_max": max(samples, default=0),
            "attacker_opened": stats["opened"],
            "attacker_answers": dict(stats["answers"]),
        }
    )


def attacker(port: int, connections: int, addresses: int, token: str | None, trickle: float,
             reopen: float, ramp: float, seconds: float, honour: bool, out: Any, ready: Any,
             ) -> None:  # fmt: skip
    """The attacker process (see the module docstring), at nice 10: its CPU is not the server host's
    in a real attack, and on a small machine it would otherwise take the server's."""
    os.nice(10)
    limit = raise_open_files(connections + 256)
    if limit < connections + 64:
        out.put({"error": f"the open-files limit is {limit}: cannot open {connections} connections"})
        ready.set()
        return
    asyncio.run(
        _attack(port, connections, addresses, token, trickle, reopen, ramp, seconds, honour, out, ready)
    )


def measure(url: str, token: str, seconds: float, interval: float) -> dict[str, Any]:
    """alice's requests, one new connection each, for ``seconds``."""
    latencies: list[float] = []
    failures: Counter[str] = Counter()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        start = time.perf_counter()
        try:
            r = httpx.get(f"{url}/v1/clips", headers={"Authorization": f"Bearer {token}"}, timeout=30)
            if r.status_code == 200:
                latencies.append(time.perf_counter() - start)
            else:
                failures[str(r.status_code)] += 1
        except httpx.HTTPError as exc:
            failures[type(exc).__name__] += 1
        time.sleep(max(0.0, interval - (time.perf_counter() - start)))
    ordered = sorted(latencies)

    def pct(q: float) -> float | None:
        return round(ordered[min(len(ordered) - 1, int(q * len(ordered)))] * 1000, 1) if ordered else None

    return {
        "requests": len(latencies) + sum(failures.values()),
        "failed": dict(failures),
        "p50_ms": pct(0.50),
        "p99_ms": pct(0.99),
        "max_ms": round(ordered[-1] * 1000, 1) if ordered else None,
    }


def slow_clients(
    connections: int = 4000,
    addresses: int = 1,
    token: str | None = "bob-token",
    seconds: float = 60.0,
    trickle: float = 12.0,
    reopen: float = 1.0,
    ramp: float = 20.0,
    interval: float = 0.1,
    env: dict[str, str] | None = None,
    honour: bool = True,
) -> dict[str, Any]:
    """One measurement (see the module docstring)."""
    root = Path(tempfile.mkdtemp(prefix="segue-slow-clients-"))
    top = Topology(root, None, workers=1, tokens=TOKENS)
    top.env |= env or {}
    try:
        top.start()
        before = measure(top.url, "alice-token", min(seconds, 10.0), interval)
        ctx = mp.get_context("spawn")
        out, ready = ctx.Queue(), ctx.Event()
        proc = ctx.Process(
            target=attacker,
            args=(
                top.port,
                connections,
                addresses,
                token,
                trickle,
                reopen,
                ramp,
                seconds,
                honour,
                out,
                ready,
            ),  # fmt: skip
        )
        proc.start()
        ready.wait(ramp + 120)
        during = measure(top.url, "alice-token", seconds, interval)
        result = out.get(timeout=seconds + 120)
        proc.join(60)
        return {
            "connections": connections,
            "addresses": addresses,
            "attacker_token": token is not None,
            "trickle_s": trickle,
            "reopen_s": reopen,
            "honours_retry_after": honour,
            "seconds": seconds,
            "settings": env or {},
            "alice_before": before,
            "alice_during": during,
            **result,
        }
    finally:
        top.stop()
        shutil.rmtree(root, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--connections", type=int, default=4000)
    ap.add_argument("--addresses", type=int, default=1)
    ap.add_argument("--token", default="bob-token", help="the attacker's token ('none': no token)")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--trickle", type=float, default=12.0, help="seconds between body bytes")
    ap.add_argument("--reopen", type=float, default=1.0, help="seconds before a closed slot reconnects")
    ap.add_argument("--ramp", type=float, default=20.0, help="seconds to open all connections")
    ap.add_argument("--interval", type=float, default=0.1, help="seconds between alice's requests")
    ap.add_argument("--flood", action="store_true", help="reconnect after --reopen whatever Retry-After says")
    ap.add_argument("--env", action="append", default=[], help="NAME=VALUE for segue serve (repeatable)")
    args = ap.parse_args()
    env = dict(item.split("=", 1) for item in args.env)
    token = None if args.token == "none" else args.token
    result = slow_clients(
        args.connections, args.addresses, token, args.seconds, args.trickle, args.reopen, args.ramp,
        args.interval, env, not args.flood,
    )  # fmt: skip
    print(json.dumps(result))


if __name__ == "__main__":
    main()
