"""A real ``uvicorn`` process running the Segue app on a free 127.0.0.1 port (embedded workers),
for tests that need real sockets: the uvicorn WebSocket tests and the browser tests."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest

REPO = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def live_server(data: Path, plugins: str | None = None, workers: int = 2) -> Iterator[str]:
    """Start ``uvicorn --factory service.app:create_app`` with a fresh data directory ``data`` (no
    tokens, no Redis; ``plugins`` = ``SEGUE_ENGINE_PLUGINS``), yield its base URL once ``/healthz``
    answers, stop it with SIGINT afterwards. Fails the test if it exits or does not answer in 120 s
    (a guard against a hang: a loaded machine may take a while to import and start it)."""
    env = os.environ | {
        "SEGUE_DATA_DIR": str(data),
        "SEGUE_WORKERS": str(workers),
        # a job's hard time limit is its budget_s plus this grace: here a guard against a hang, not a
        # bar a busy machine could trip (an engine process loading librosa at load 15 took > 30 s)
        "SEGUE_JOB_GRACE_S": "600",
        "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
    }
    for var in ("SEGUE_API_TOKENS", "SEGUE_REDIS_URL", "SEGUE_ENGINE_PLUGINS"):
        env.pop(var, None)
    if plugins:
        env["SEGUE_ENGINE_PLUGINS"] = plugins
    port = free_port()
    command = [sys.executable, "-m", "uvicorn", "--factory", "service.app:create_app",
               "--host", "127.0.0.1", "--port", str(port), "--log-level", "warning"]  # fmt: skip
    with serving(command, env, port, data / "uvicorn.log", signal.SIGINT) as url:
        yield url


@contextmanager
def serving(
    command: list[str], env: dict[str, str], port: int, log_path: Path, stop: int = signal.SIGTERM
) -> Iterator[str]:
    """Run ``command`` (a server listening on 127.0.0.1:``port``; its output in ``log_path``) from
    the repository, yield its base URL once ``/healthz`` answers, then stop it with ``stop``
    (killed after 20 s). Fails the test if it exits first or does not answer within 120 s (a hang
    guard: a loaded machine may take a while to import and start it)."""
    with log_path.open("wb") as log:
        proc = subprocess.Popen(command, cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT)
        url = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 120
        while True:
            if proc.poll() is not None:
                pytest.fail(f"{command[2]} exited with {proc.returncode}: {log_path.read_text()[-2000:]}")
            try:
                if httpx.get(f"{url}/healthz", timeout=5).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline:
                proc.kill()
                pytest.fail(f"{command[2]} did not answer /healthz within 120 s")
            time.sleep(0.05)
        try:
            yield url
        finally:
            proc.send_signal(stop)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
