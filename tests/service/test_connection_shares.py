"""One token holder cannot lock the others out (issue 40, item 1), on a real ``segue serve`` (a
subprocess on a free 127.0.0.1 port, two tokens, small limits): connections per client address
and per principal are capped below the server's total, a request with a body but no valid token is
refused before its body is read, a body trickling below the minimum rate or outlasting the request
deadline gets 408 and its connection closed, and a WebSocket outlives that deadline and counts
towards its principal's share. Another principal is served throughout.

Other client addresses are 127.0.0.2, 127.0.0.3 (a socket bound there before connecting: Linux
routes all of 127.0.0.0/8 to the loopback). No wall-clock asserts: the limits are small and the
clients' pauses far from them.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import ClientConnection, connect

from tests.live_server import REPO, free_port, serving

from .conftest import PLUGINS, WALK

GUARD_S = 120.0
TOKENS = {"alice": "alice-token", "bob": "bob-token"}


@contextlib.contextmanager
def segue_serve(data: Path, **limits: str) -> Iterator[str]:
    """``segue serve`` with tokens and the given ``SEGUE_*`` limits; its base URL once it answers."""
    env = (
        os.environ
        | {
            "SEGUE_DATA_DIR": str(data),
            "SEGUE_API_TOKENS": ",".join(f"{k}:{v}" for k, v in TOKENS.items()),
            "SEGUE_ENGINE_PLUGINS": PLUGINS,
            "SEGUE_JOB_GRACE_S": "600",
            "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
        }
        | {f"SEGUE_{k.upper()}": v for k, v in limits.items()}
    )
    env.pop("SEGUE_REDIS_URL", None)
    port = free_port()
    command = [sys.executable, "-m", "service.cli", "serve", "--port", str(port), "--workers", "1",
               "--no-warm", "--log-level", "warning"]  # fmt: skip
    with serving(command, env, port, data / "serve.log") as url:
        yield url


def port_of(url: str) -> int:
    return int(url.rsplit(":", 1)[1])


def open_from(url: str, source: str = "127.0.0.1") -> socket.socket:
    """A connection to the server from client address ``source``."""
    sock = socket.socket()
    sock.bind((source, 0))
    sock.settimeout(GUARD_S)
    sock.connect(("127.0.0.1", port_of(url)))
    return sock


def upload_head(token: str | None, length: int = 100_000, json_route: bool = False) -> bytes:
    """The headers of a raw-body clip upload (or a job's JSON) announcing ``length`` bytes."""
    auth = f"Authorization: Bearer {token}\r\n" if token else ""
    target, kind = ("/v1/jobs", "application/json") if json_route else (
        "/v1/clips?name=slow.bvh", "application/octet-stream")  # fmt: skip
    return (
        f"POST {target} HTTP/1.1\r\nHost: localhost\r\n{auth}"
        f"Content-Type: {kind}\r\nContent-Length: {length}\r\n\r\n"
    ).encode()


def answer_and_eof(sock: socket.socket) -> bytes:
    """Everything the server sends until it closes the connection (fails the test past the guard)."""
    received = b""
    with contextlib.suppress(ConnectionResetError):
        while chunk := sock.recv(65536):
            received += chunk
    return received


def trickle_until_closed(sock: socket.socket, pause: float = 0.25) -> tuple[bytes, bool]:
    """Send a body byte every ``pause`` seconds, reading what comes back, until the server closes
    the connection (True) or the guard passes (False)."""
    sock.settimeout(pause)
    answer = b""
    for _ in range(int(GUARD_S / pause)):
        try:
            sock.sendall(b"x")
            chunk = sock.recv(65536)
        except TimeoutError:
            continue
        except OSError:  # reset, broken pipe: closed
            return answer, True
        if not chunk:
            return answer, True
        answer += chunk
    return answer, False


def status_of(answer: bytes) -> int:
    return int(answer.split(b" ", 2)[1]) if answer.startswith(b"HTTP/1.1 ") else 0


def error_code(answer: bytes) -> str:
    return str(json.loads(answer.split(b"\r\n\r\n", 1)[1])["error"]["code"])


def served(url: str, who: str = "alice") -> int:
    """The status of one ``GET /v1/clips`` of ``who`` on a new connection from 127.0.0.1."""
    headers = {"Authorization": f"Bearer {TOKENS[who]}"}
    return httpx.get(f"{url}/v1/clips", headers=headers, timeout=GUARD_S).status_code


def trickle(url: str, token: str, source: str) -> socket.socket:
    """An upload whose body has begun (one byte) and waits for the rest; served by now."""
    sock = open_from(url, source)
    sock.sendall(upload_head(token) + b"x")
    return sock


def events_socket(url: str, job: str, token: str) -> ClientConnection:
    ws_url = f"ws{url.removeprefix('http')}/v1/jobs/{job}/events?token={token}"
    return connect(ws_url, open_timeout=GUARD_S)


def long_job(url: str, token: str, steps: int) -> str:
    """A scripted job of ``steps`` solutions 0.25 s apart on a database of the walk sample."""
    http = httpx.Client(base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=GUARD_S)
    with http:
        clip = http.post("/v1/clips", params={"name": WALK.name}, content=WALK.read_bytes())
        assert clip.status_code in (200, 201), clip.text
        spec = {"kind": "clips", "clips": [{"bvh": WALK.name}], "fps": 30}
        db = http.post("/v1/databases", json=spec).json()["id"]
        deadline = time.monotonic() + GUARD_S
        while http.get(f"/v1/databases/{db}").json()["status"] != "ready":
            assert time.monotonic() < deadline, "the database was not built in time"
            time.sleep(0.1)
        request = {"engine": "scripted", "database": db, "steps": steps, "step_s": 0.25}
        job = http.post("/v1/jobs", json=request)
        assert job.status_code == 202, job.text
        return str(job.json()["id"])


@pytest.fixture(scope="module")
def shares(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    data = tmp_path_factory.mktemp("shares")
    with segue_serve(
        data,
        max_connections="64",
        max_connections_per_address="6",
        max_connections_per_principal="3",
        request_timeout_s="300",
        min_body_rate="0",
    ) as url:
        yield url


def test_an_address_beyond_its_share_is_refused_and_others_served(shares: str) -> None:
    held = [open_from(shares, "127.0.0.2") for _ in range(6)]  # idle: no request yet
    try:
        extra = open_from(shares, "127.0.0.2")
        answer = answer_and_eof(extra)
        extra.close()
        assert status_of(answer) == 503 and error_code(answer) == "too_many_connections"
        assert b"retry-after" in answer.lower()
        assert served(shares) == 200  # another address
        held.pop().close()
        deadline = time.monotonic() + GUARD_S
        while True:  # the freed slot is the address's again (once the server saw the close)
            again = open_from(shares, "127.0.0.2")
            again.sendall(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n")
            if status_of(answer_and_eof(again)) == 200:
                again.close()
                break
            again.close()
            assert time.monotonic() < deadline, "a freed address slot was never reused"
            time.sleep(0.05)
    finally:
        for sock in held:
            sock.close()


def test_a_principal_beyond_its_share_is_refused_before_its_body(shares: str) -> None:
    # bob's three uploads are in progress from three addresses (so no address share is reached)
    uploads = [trickle(shares, TOKENS["bob"], f"127.0.0.{3 + k % 2}") for k in range(3)]
    try:
        deadline = time.monotonic() + GUARD_S
        while served(shares, "bob") != 503:  # the server has read the three requests' headers
            assert time.monotonic() < deadline, "bob's fourth request was never refused"
            time.sleep(0.05)
        fourth = open_from(shares, "127.0.0.4")
        fourth.sendall(upload_head(TOKENS["bob"]))  # no body byte sent: refused on its headers
        answer = answer_and_eof(fourth)  # and the connection closed
        fourth.close()
        assert status_of(answer) == 503 and error_code(answer) == "too_many_connections"
        assert served(shares, "alice") == 200
    finally:
        for sock in uploads:
            sock.close()
    deadline = time.monotonic() + GUARD_S
    while served(shares, "bob") != 200:  # his share is his again once they ended
        assert time.monotonic() < deadline, "bob's share was not freed"
        time.sleep(0.05)


def test_a_body_without_a_valid_token_is_refused_before_it_is_read(shares: str) -> None:
    for token, json_route in ((None, False), ("not-a-token", False), (None, True)):
        sock = open_from(shares, "127.0.0.2")
        sock.sendall(upload_head(token, json_route=json_route) + b"{")  # 99,999 bytes owed
        answer, closed = trickle_until_closed(sock)  # the body goes on trickling after the answer
        sock.close()
        assert closed, "the connection stayed open after its 401"
        assert status_of(answer) == 401
        assert error_code(answer) == ("unauthorized" if token is None else "invalid_token")
        assert b"www-authenticate: bearer" in answer.lower()


def test_websockets_count_towards_their_principal(shares: str) -> None:
    job = long_job(shares, TOKENS["bob"], steps=400)  # 100 s of events: open until cancelled
    with contextlib.ExitStack() as stack:
        sockets = [stack.enter_context(events_socket(shares, job, TOKENS["bob"])) for _ in range(3)]
        for ws in sockets:
            assert json.loads(ws.recv(timeout=GUARD_S))["id"] >= 1  # streaming
        assert served(shares, "bob") == 503  # his three WebSockets are his share
        assert served(shares, "alice") == 200
        with pytest.raises(InvalidStatus) as refused, events_socket(shares, job, TOKENS["bob"]):
            pass
        assert refused.value.response.status_code == 503
    deadline = time.monotonic() + GUARD_S
    while served(shares, "bob") != 200:
        assert time.monotonic() < deadline, "closed WebSockets still counted"
        time.sleep(0.05)
    headers = {"Authorization": f"Bearer {TOKENS['bob']}"}
    httpx.post(f"{shares}/v1/jobs/{job}/cancel", headers=headers, timeout=GUARD_S)


@pytest.fixture(scope="module")
def deadlines(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    data = tmp_path_factory.mktemp("deadlines")
    with segue_serve(
        data,
        request_timeout_s="3",  # these bodies never pause that long: the rate or the deadline cuts them
        request_deadline_s="4",
        min_body_rate="1000",
        body_rate_grace_s="1",
    ) as url:
        yield url


def send_until_answered(sock: socket.socket, piece: bytes, every_s: float) -> bytes:
    """Send ``piece`` every ``every_s`` seconds until the server answers and closes (or the hang
    guard); what it answered. The socket is closed after."""
    sock.settimeout(every_s)
    answer = b""
    for _ in range(int(GUARD_S / every_s)):
        try:
            sock.sendall(piece)
        except OSError:
            break
        try:
            chunk = sock.recv(65536)
        except TimeoutError:
            continue
        except ConnectionResetError:
            break
        answer += chunk
        if not chunk:
            break
    sock.close()
    return answer


def test_a_body_below_the_minimum_rate_gets_408(deadlines: str) -> None:
    sock = open_from(deadlines, "127.0.0.2")
    sock.sendall(upload_head(TOKENS["bob"]))
    answer = send_until_answered(sock, b"x", 0.2)  # one byte every 0.2 s: 5 bytes/s against 1000
    assert status_of(answer) == 408 and error_code(answer) == "request_timeout"
    assert served(deadlines, "alice") == 200


def test_a_body_past_the_request_deadline_gets_408(deadlines: str) -> None:
    sock = open_from(deadlines, "127.0.0.2")
    sock.sendall(upload_head(TOKENS["bob"], length=10_000_000))
    answer = send_until_answered(sock, b"x" * 20_000, 0.25)  # 80 kB/s, far above the rate, for 125 s
    assert status_of(answer) == 408 and error_code(answer) == "request_timeout"


def test_a_websocket_outlives_the_request_timeouts(deadlines: str) -> None:
    job = long_job(deadlines, TOKENS["alice"], steps=32)  # 8 s of events: twice the deadline
    events = []
    with events_socket(deadlines, job, TOKENS["alice"]) as ws:
        for message in ws:
            events.append(json.loads(message))
    assert events[-1]["type"] == "done"
    assert sum(e["type"] == "solution" for e in events) == 32


def test_a_long_poll_outlives_the_request_timeouts(deadlines: str) -> None:
    job = long_job(deadlines, TOKENS["alice"], steps=32)  # ends in 8 s: twice the deadline
    headers = {"Authorization": f"Bearer {TOKENS['alice']}"}
    r = httpx.get(f"{deadlines}/v1/jobs/{job}/events?wait=60", headers=headers, timeout=GUARD_S)
    assert r.status_code == 200 and r.json()[-1]["type"] == "done"
