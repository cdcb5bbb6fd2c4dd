"""Redis across hosts: a password (``requirepass``) and TLS (``rediss://``), as README's three-host
deployment runs it, against real ``redis-server`` processes: the API and a worker run a job through
each URL form Segue's settings accept, and a worker given a wrong password stops with a clear error
instead of retrying for ever.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime
import ipaddress
import shutil
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import quote

import pytest
import redis

from schemas import EventType, JobEvent
from workers.redis_backend import RedisBackend
from workers.redis_worker import serve
from workers.settings import Settings
from workers.store import Store

from .conftest import GUARD_S, _free_port, add_database, run, synth, worker_thread

PASSWORD = "s3cret/with:reserved@chars"
"""URL-reserved characters: the URL carries it percent-encoded."""


@contextlib.contextmanager
def _server(args: list[str], tmp_path: Path, check: redis.Redis) -> Iterator[None]:
    """A redis-server with ``args`` until the block ends (``check`` pings it until it answers)."""
    binary = shutil.which("redis-server")
    if binary is None:
        pytest.skip("redis-server is not installed")
    proc = subprocess.Popen(
        [binary, "--bind", "127.0.0.1", "--save", "", "--appendonly", "no", "--dir", str(tmp_path), *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + GUARD_S
    while True:
        try:
            check.ping()
            break
        except redis.ConnectionError:
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                pytest.fail("redis-server did not start")
            time.sleep(0.05)
    try:
        yield
    finally:
        check.close()
        proc.terminate()
        proc.wait(timeout=GUARD_S)


@pytest.fixture
def password_url(tmp_path: Path) -> Iterator[str]:
    port = _free_port()
    url = f"redis://:{quote(PASSWORD, safe='')}@127.0.0.1:{port}/0"
    check = redis.Redis.from_url(url)
    with _server(["--port", str(port), "--requirepass", PASSWORD], tmp_path, check):
        yield url


def _certificates(tmp_path: Path) -> tuple[Path, Path, Path]:
    """A private CA and a server certificate for 127.0.0.1 (PEM files: ca, cert, key)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    now = datetime.datetime.now(datetime.UTC)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "segue test CA")])
    ca = (
        x509.CertificateBuilder()
        .subject_name(ca_name)
        .issuer_name(ca_name)
        .public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .sign(ca_key, hashes.SHA256())
    )
    key = ec.generate_private_key(ec.SECP256R1())
    cert = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "127.0.0.1")]))
        .issuer_name(ca_name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(
            x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False
        )
        .sign(ca_key, hashes.SHA256())
    )
    paths = tmp_path / "ca.crt", tmp_path / "redis.crt", tmp_path / "redis.key"
    paths[0].write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    paths[1].write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    paths[2].write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
        )
    )
    return paths


@pytest.fixture
def tls_url(tmp_path: Path) -> Iterator[str]:
    """A redis-server on TLS only (no plain port), with a password; the URL trusts its CA."""
    ca, cert, key = _certificates(tmp_path)
    port = _free_port()
    url = f"rediss://:{quote(PASSWORD, safe='')}@127.0.0.1:{port}/0?ssl_ca_certs={ca}"
    args = ["--port", "0", "--tls-port", str(port), "--tls-cert-file", str(cert), "--tls-key-file", str(key)]
    args += ["--tls-ca-cert-file", str(ca), "--tls-auth-clients", "no", "--requirepass", PASSWORD]
    with _server(args, tmp_path, redis.Redis.from_url(url)):
        yield url


def _one_job(url: str, store: Store) -> list[JobEvent]:
    db = add_database(store)

    async def scenario() -> list[JobEvent]:
        backend = RedisBackend(store, url, block_ms=200)
        await backend.start()
        try:
            assert (await backend.health())["redis"] == "ok"
            info, payload = synth(store, db, steps=2, step_s=0.0)
            await backend.submit(info, "synth", payload)
            return await asyncio.wait_for(_all(backend, info.id), GUARD_S)
        finally:
            await backend.close()

    with worker_thread(url, store, "w1"):
        return run(scenario())


async def _all(backend: RedisBackend, job_id: str) -> list[JobEvent]:
    return [e async for e in backend.events(job_id)]


def test_a_password_url_runs_jobs_on_a_redis_with_requirepass(password_url: str, store: Store) -> None:
    events = _one_job(password_url, store)
    assert events[-1].type == EventType.done


def test_a_wrong_password_stops_the_worker_with_a_clear_error(
    password_url: str, store: Store, caplog: pytest.LogCaptureFixture
) -> None:
    wrong = password_url.replace(quote(PASSWORD, safe=""), "not-it")
    settings = Settings(redis_url=wrong, store_url=store.url, data_dir=store.root, worker_name="w1")
    status: list[int] = []
    thread = threading.Thread(target=lambda: status.append(serve(settings, warm=False)), daemon=True)
    thread.start()
    thread.join(GUARD_S)  # at once, not retried for ever (a hang guard, not a pace)
    assert status == [1]
    assert "check the password in SEGUE_REDIS_URL" in caplog.text
    assert "not-it" not in repr(settings)  # nor is it ever printed


def test_a_tls_url_runs_jobs_on_a_redis_that_speaks_only_tls(tls_url: str, store: Store) -> None:
    plain = tls_url.replace("rediss://", "redis://").split("?")[0]
    with pytest.raises(redis.ConnectionError):  # the server speaks nothing else
        redis.Redis.from_url(plain, socket_timeout=5).ping()
    events = _one_job(tls_url, store)
    assert events[-1].type == EventType.done
