"""``segue serve``'s connection limits on a real uvicorn server (a thread of this process, the
options ``segue serve`` passes, :func:`service.server.uvicorn_options`): a client that drips its
headers, or stalls in its body, is disconnected after the request timeout; connections beyond the
limit get 503 at once; well-behaved clients are served throughout."""

from __future__ import annotations

import contextlib
import select
import socket
import threading
import time
from collections.abc import Iterator

import httpx
import pytest
import uvicorn
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import PlainTextResponse
from starlette.routing import Route

from service.server import BUSY, uvicorn_options
from service.settings import Settings

GUARD_S = 60.0


async def echo(request: Request) -> PlainTextResponse:
    return PlainTextResponse(f"{len(await request.body())} bytes")


APP = Starlette(routes=[Route("/", echo, methods=["GET", "POST"])])


@contextlib.contextmanager
def server(**limits: float) -> Iterator[int]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    options = uvicorn_options(Settings(**limits))
    config = uvicorn.Config(APP, host="127.0.0.1", port=port, log_level="warning", **options)
    srv = uvicorn.Server(config)
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + GUARD_S
    while not srv.started:
        if time.monotonic() > deadline:
            pytest.fail("the server did not start")
        time.sleep(0.02)
    try:
        yield port
    finally:
        srv.should_exit = True
        thread.join(GUARD_S)


def closed_by_server(sock: socket.socket) -> bool:
    """True once the server closed the connection (EOF or reset), without blocking."""
    readable, _, _ = select.select([sock], [], [], 0)
    if not readable:
        return False
    try:
        return sock.recv(65536) == b""
    except ConnectionError:
        return True


def test_slow_headers_and_stalled_bodies_are_cut(monkeypatch: pytest.MonkeyPatch) -> None:
    with server(request_timeout_s=1.0) as port:
        loris = socket.create_connection(("127.0.0.1", port))
        loris.sendall(b"GET / HTTP/1.1\r\nHost: localhost\r\n")
        deadline = time.monotonic() + GUARD_S
        cut = False
        while time.monotonic() < deadline and not cut:
            try:
                loris.sendall(b"X-Drip: 1\r\n")  # a byte now and then: never a whole request
            except OSError:
                cut = True
                break
            time.sleep(0.2)
            cut = closed_by_server(loris)
        assert cut, "a connection dripping its headers was held"
        loris.close()

        stall = socket.create_connection(("127.0.0.1", port))
        stall.sendall(b"POST / HTTP/1.1\r\nHost: localhost\r\nContent-Length: 100\r\n\r\n0123456789")
        stall.settimeout(GUARD_S)
        received = b""
        with contextlib.suppress(ConnectionError):
            while chunk := stall.recv(65536):
                received += chunk
        assert b"200 OK" not in received  # cut before the body was whole
        stall.close()
        assert httpx.get(f"http://127.0.0.1:{port}/", timeout=GUARD_S).text == "0 bytes"

    # a slow but moving upload is not cut: 16 chunks 0.25 s apart, 4 s in all, past a 3-s timeout
    # (each pause is 2.75 s inside it: a loaded machine may be late with a chunk without the
    # connection being cut; with a 1-s timeout and 0.5-s pauses a 0.5-s stall of this process cut it)
    with server(request_timeout_s=3.0) as port:
        moving = socket.create_connection(("127.0.0.1", port))
        moving.sendall(b"POST / HTTP/1.1\r\nHost: localhost\r\nContent-Length: 160\r\n\r\n")
        for _ in range(16):  # sleeps of 4 s in all: the upload outlasts the timeout
            time.sleep(0.25)
            moving.sendall(b"0123456789")
        moving.settimeout(GUARD_S)
        reply = b""
        while b"bytes" not in reply and (chunk := moving.recv(65536)):
            reply += chunk
        assert reply.startswith(b"HTTP/1.1 200 OK") and reply.endswith(b"160 bytes")
        moving.close()
        assert httpx.get(f"http://127.0.0.1:{port}/", timeout=GUARD_S).text == "0 bytes"


def test_connections_beyond_the_limit_get_503() -> None:
    with server(max_connections=10, request_timeout_s=GUARD_S) as port:
        held = [socket.create_connection(("127.0.0.1", port)) for _ in range(10)]
        extra = socket.create_connection(("127.0.0.1", port))
        extra.settimeout(GUARD_S)
        answer = b""
        with contextlib.suppress(ConnectionError):
            while chunk := extra.recv(65536):
                answer += chunk
        assert answer == BUSY
        extra.close()
        held.pop().close()

        def served() -> bool:
            try:
                return httpx.get(f"http://127.0.0.1:{port}/", timeout=GUARD_S).status_code == 200
            except httpx.HTTPError:
                return False

        deadline = time.monotonic() + GUARD_S
        while not served():
            assert time.monotonic() < deadline, "a freed connection slot was never reused"
            time.sleep(0.05)
        for sock in held:
            sock.close()
