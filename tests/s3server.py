"""A real S3-protocol server for the tests: moto's server mode (``moto_server``), on a free port,
with each request atomic as S3's are (``tests/moto_atomic.py`` says why).

Never a mock of our own: the store talks HTTP to this server exactly as it would to MinIO or AWS.
``moto[server]`` is in the dev extra; without it the S3 tests fail under CI (``CI=true``) and are
skipped elsewhere with the reason.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

GUARD_S = 120.0
ATOMIC = Path(__file__).with_name("moto_atomic.py")  # moto, each request atomic (its docstring)
CREDENTIALS = {
    "AWS_ACCESS_KEY_ID": "testing",
    "AWS_SECRET_ACCESS_KEY": "testing",
    "AWS_DEFAULT_REGION": "us-east-1",
    "AWS_REGION": "us-east-1",
}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def moto_server() -> Iterator[str]:
    """Start ``moto_server`` on a free port; yields its endpoint URL; stops it on exit."""
    binary = shutil.which("moto_server")
    if binary is None:
        reason = "moto_server is not installed (pip install 'moto[server]'); the S3 store tests need it"
        if os.environ.get("CI") == "true":
            pytest.fail(reason)
        pytest.skip(reason)
    for _attempt in range(3):
        port = _free_port()
        proc = subprocess.Popen(
            [sys.executable, str(ATOMIC), "-H", "127.0.0.1", "-p", str(port)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        endpoint = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + GUARD_S
        up = False
        while proc.poll() is None and time.monotonic() < deadline:
            try:
                with urllib.request.urlopen(f"{endpoint}/", timeout=5):
                    up = True
                    break
            except (urllib.error.URLError, OSError):
                time.sleep(0.05)
        if not up:
            proc.kill()
            proc.wait()
            continue
        try:
            yield endpoint
        finally:
            stop_server(proc)
        return
    pytest.fail("could not start moto_server")


def stop_server(proc: subprocess.Popen[bytes]) -> None:
    """Terminate a test server process and wait for it (killed after the hang guard)."""
    proc.terminate()
    try:
        proc.wait(timeout=GUARD_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@contextlib.contextmanager
def aws_environment(endpoint: str) -> Iterator[None]:
    """The standard AWS variables pointing at ``endpoint`` (inherited by spawned processes)."""
    saved = {k: os.environ.get(k) for k in (*CREDENTIALS, "AWS_ENDPOINT_URL")}
    os.environ.update(CREDENTIALS, AWS_ENDPOINT_URL=endpoint)
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def new_bucket(endpoint: str) -> str:
    """A fresh bucket on the server (a test's own); its name."""
    import boto3

    name = f"segue-{uuid.uuid4().hex[:12]}"
    boto3.client("s3", endpoint_url=endpoint, **_client_credentials()).create_bucket(Bucket=name)
    return name


def _client_credentials() -> dict[str, str]:
    return {
        "aws_access_key_id": CREDENTIALS["AWS_ACCESS_KEY_ID"],
        "aws_secret_access_key": CREDENTIALS["AWS_SECRET_ACCESS_KEY"],
        "region_name": CREDENTIALS["AWS_REGION"],
    }
