"""Fixtures of the Blender add-on's tests: a real ``segue serve`` on a free port, the add-on zip
``segue blender-addon`` writes, and databases built from bundled samples."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.live_server import free_port

REPO = Path(__file__).resolve().parents[2]
SEGUE = Path(sys.executable).with_name("segue")
HANG_GUARD_S = 120.0


class Serve:
    """A running ``segue serve`` (its URL, data folder and log)."""

    def __init__(self, url: str, data: Path, proc: subprocess.Popen[bytes]) -> None:
        self.url, self.data, self.proc = url, data, proc

    def client(self) -> Any:
        from service.client import SegueClient

        return SegueClient(self.url, timeout=120)


def start_serve(data: Path, *extra: str) -> Serve:
    """``segue serve --port P --data DATA`` (embedded workers), once ``/healthz`` answers (a
    120-s hang guard: a loaded machine imports the service slowly)."""
    port = free_port()
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("SEGUE_API_TOKENS", "SEGUE_REDIS_URL", "SEGUE_ENGINE_PLUGINS")
    }
    env["SEGUE_JOB_GRACE_S"] = "600"
    data.mkdir(parents=True, exist_ok=True)
    log = (data / "serve.log").open("wb")
    proc = subprocess.Popen(
        [str(SEGUE), "serve", "--port", str(port), "--data", str(data), "--log-level", "warning", *extra],
        cwd=data, env=env, stdout=log, stderr=subprocess.STDOUT,
    )  # fmt: skip
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + HANG_GUARD_S
    while True:
        if proc.poll() is not None:
            pytest.fail(
                f"segue serve exited with {proc.returncode}: {(data / 'serve.log').read_text()[-2000:]}"
            )
        try:
            if httpx.get(f"{url}/healthz", timeout=1).status_code == 200:
                return Serve(url, data, proc)
        except httpx.TransportError:
            pass
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"segue serve did not answer /healthz within {HANG_GUARD_S:.0f} s")
        time.sleep(0.1)


def stop_serve(serve: Serve) -> None:
    serve.proc.send_signal(signal.SIGINT)
    try:
        serve.proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        serve.proc.kill()
        serve.proc.wait()


@pytest.fixture(scope="module")
def serve(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Serve]:
    s = start_serve(tmp_path_factory.mktemp("segue-data"))
    try:
        yield s
    finally:
        stop_serve(s)


@pytest.fixture(scope="module")
def addon_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The zip the real command writes (``segue blender-addon --out``)."""
    out = tmp_path_factory.mktemp("addon") / "segue_blender.zip"
    r = subprocess.run(
        [str(SEGUE), "blender-addon", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    return out
