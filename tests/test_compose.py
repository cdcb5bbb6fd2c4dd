"""The compose files' shape, checked by parsing them (no Docker daemon is needed, none is used).

``docker-compose.yml``, one host: an API, two workers, Redis, MinIO and a one-shot bucket creation;
no volume shared by Segue's processes (each container's disk is a cache only); every Segue process
on the same object store and the same Redis, which asks for a password and keeps an append-only
file. ``deploy/*.compose.yml``, three hosts (one file per role, the addresses and secrets in
``deploy/hosts.env``): Redis on TLS only, reached with ``rediss://`` URLs that Segue's settings and
redis-py accept as they are. Every image is pinned (no ``latest``, no bare tag).
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

import pytest
import yaml
from redis.connection import SSLConnection, parse_url

from workers.objects import S3Objects, open_objects
from workers.settings import Settings

REPO = Path(__file__).resolve().parents[1]
DEPLOY = REPO / "deploy"
VERSION = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]
VARIABLE = re.compile(r"\$\{(\w+)(?:(:?[-?])([^}]*))?\}")


def hosts_env() -> dict[str, str]:
    """The example hosts file's variables (``KEY=value`` lines)."""
    env = {}
    for line in (DEPLOY / "hosts.env.example").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            key, value = line.split("=", 1)
            env[key.strip()] = value.strip()
    return env


def interpolate(text: str, env: dict[str, str]) -> str:
    """Compose's ``${VAR}``, ``${VAR:-default}`` and ``${VAR:?error}``; ``$$`` stays ``$``."""

    def one(match: re.Match[str]) -> str:
        name, op, arg = match.group(1), match.group(2), match.group(3)
        if env.get(name):
            return env[name]
        if op and op.endswith("-"):
            return str(arg)
        raise AssertionError(f"{name} is required: {arg}")

    return VARIABLE.sub(one, text).replace("$$", "$")


def compose(path: Path, env: dict[str, str] | None = None) -> dict[str, Any]:
    return dict(yaml.safe_load(interpolate(path.read_text(), env or {})))


def one_host() -> dict[str, Any]:
    return compose(REPO / "docker-compose.yml")["services"]


def role(name: str) -> dict[str, Any]:
    return compose(DEPLOY / f"{name}.compose.yml", hosts_env())["services"]


def redis_args(service: dict[str, Any]) -> str:
    return " ".join(service["command"])


def test_services_are_the_api_two_workers_redis_minio_and_the_bucket() -> None:
    services = one_host()
    assert set(services) == {"api", "worker", "redis", "minio", "bucket"}
    assert services["worker"]["deploy"]["replicas"] == 2
    assert services["api"]["command"][:2] == ["segue", "serve"]
    assert services["worker"]["command"] == ["segue", "worker"]
    assert services["minio"]["image"].startswith("minio/minio")
    assert services["bucket"]["image"].startswith("minio/mc")
    for name in ("api", "worker"):
        assert services[name]["depends_on"]["bucket"] == {"condition": "service_completed_successfully"}


def test_no_volume_is_shared_and_segue_processes_mount_none() -> None:
    compose_file = compose(REPO / "docker-compose.yml")
    services = compose_file["services"]
    for name in ("api", "worker", "bucket"):
        assert "volumes" not in services[name], f"{name} mounts a volume: its disk must be a cache only"
    mounts = [v.split(":")[0] for s in services.values() for v in s.get("volumes", [])]
    assert sorted(mounts) == ["minio-objects", "redis-aof"]  # each the disk of one service
    assert set(compose_file.get("volumes", {})) == set(mounts)


def test_api_and_workers_use_the_same_store_and_redis_and_the_bucket_service_creates_it() -> None:
    services = one_host()
    shared = (
        "SEGUE_STORE_URL",
        "AWS_ENDPOINT_URL",
        "AWS_ACCESS_KEY_ID",
        "AWS_SECRET_ACCESS_KEY",
        "SEGUE_REDIS_URL",
    )
    envs = [services[name]["environment"] for name in ("api", "worker")]
    for key in shared:
        assert envs[0][key] == envs[1][key], key
    env = envs[0]
    objects = open_objects(env["SEGUE_STORE_URL"])
    assert isinstance(objects, S3Objects)
    minio = services["minio"]["environment"]
    assert (minio["MINIO_ROOT_USER"], minio["MINIO_ROOT_PASSWORD"]) == (
        env["AWS_ACCESS_KEY_ID"],
        env["AWS_SECRET_ACCESS_KEY"],
    )
    assert env["AWS_ENDPOINT_URL"] == "http://minio:9000"
    bucket = services["bucket"]
    assert f"store/{objects.bucket}" in bucket["command"][0] and "http://minio:9000" in bucket["command"][0]
    assert bucket["environment"] == minio


def test_redis_asks_for_a_password_and_keeps_an_append_only_file() -> None:
    services = one_host()
    redis = services["redis"]
    args = redis_args(redis)
    assert '--requirepass "$REDIS_PASSWORD"' in args
    assert "--appendonly yes" in args and "--appendfsync everysec" in args
    assert "--maxmemory-policy noeviction" in args and '--save ""' in args
    assert redis["volumes"] == ["redis-aof:/data"]  # the append-only file outlives the container
    url = parse_url(services["api"]["environment"]["SEGUE_REDIS_URL"])
    assert url["password"] == redis["environment"]["REDIS_PASSWORD"]
    assert redis["environment"]["REDISCLI_AUTH"] == url["password"]  # the health check's
    assert (url["host"], url["port"]) == ("redis", 6379)


def test_segue_processes_get_redis_in_the_environment_never_on_a_command_line() -> None:
    """``ps`` shows a command line to every user of the host; the URL carries the password."""
    for services in (one_host(), role("api"), role("worker")):
        for name in ("api", "worker"):
            if name in services:
                assert not any("redis" in arg for arg in services[name]["command"])
                assert "SEGUE_REDIS_URL" in services[name]["environment"]


def test_every_image_is_pinned() -> None:
    images = [s["image"] for s in one_host().values()]
    for name in ("state", "api", "worker"):
        images += [s["image"] for s in role(name).values()]
    for image in images:
        tag = image.rsplit(":", 1)[1] if ":" in image else ""
        assert tag and tag != "latest", f"{image} is not pinned"
        if image.startswith("minio/"):
            assert re.fullmatch(r"RELEASE\.\d{4}-\d\d-\d\dT\d\d-\d\d-\d\dZ", tag), image
        elif image.startswith("redis:"):
            assert re.fullmatch(r"\d+\.\d+\.\d+", tag), image
        else:
            assert image == f"segue:{VERSION}", image  # the API and its workers: this package's version
    base = re.search(r"^FROM (\S+)", (REPO / "Dockerfile").read_text(), re.M)
    assert base is not None and re.fullmatch(r"python:3\.11\.\d+-slim-\w+", base.group(1))


def test_aws_region_is_the_standard_variable() -> None:
    """``AWS_REGION`` (every AWS SDK's, the AWS CLI v2's; Segue passes it to boto3), not the
    CLI-only ``AWS_DEFAULT_REGION``."""
    for services in (one_host(), role("api"), role("worker")):
        for name in ("api", "worker"):
            if name in services:
                env = services[name]["environment"]
                assert env["AWS_REGION"] and "AWS_DEFAULT_REGION" not in env


def test_three_hosts_one_file_per_role() -> None:
    env = hosts_env()
    state, api, worker = role("state"), role("api")["api"], role("worker")["worker"]
    assert set(state) == {"redis", "minio", "bucket"}
    assert api["command"][:2] == ["segue", "serve"] and worker["command"] == ["segue", "worker"]
    assert int(worker["deploy"]["replicas"]) == int(env["WORKERS_PER_HOST"])
    shared = ("SEGUE_REDIS_URL", "SEGUE_STORE_URL", "AWS_ENDPOINT_URL", "AWS_CA_BUNDLE", "AWS_ACCESS_KEY_ID")
    for key in (*shared, "AWS_SECRET_ACCESS_KEY", "AWS_REGION"):
        assert api["environment"][key] == worker["environment"][key], key
    assert api["environment"]["AWS_ENDPOINT_URL"] == f"https://{env['STATE_HOST']}:9000"
    assert api["environment"]["SEGUE_ALLOWED_HOSTS"] == env["API_HOST"]
    assert api["environment"]["SEGUE_API_TOKENS"] == env["SEGUE_API_TOKENS"]
    for service in (api, worker):
        assert service["volumes"] == ["./tls/ca.crt:/tls/ca.crt:ro"]  # the CA only, no data volume
        assert service["build"] == ".."  # this checkout, tagged with its version
    assert "ports" not in worker  # workers take jobs from Redis, nobody connects to them


def test_redis_between_hosts_is_tls_only_with_a_password_and_an_append_only_file() -> None:
    env = hosts_env()
    redis = role("state")["redis"]
    args = redis_args(redis)
    assert "--port 0 --tls-port 6380" in args  # no plain-text port at all
    assert "--tls-cert-file /tls/state.crt" in args and "--tls-key-file /tls/state.key" in args
    assert (
        '--requirepass "$REDIS_PASSWORD"' in args
        and redis["environment"]["REDIS_PASSWORD"] == env["REDIS_PASSWORD"]
    )
    assert "--appendonly yes" in args and "redis-aof:/data" in redis["volumes"]
    assert redis["ports"] == ["6380:6380"]
    url = role("worker")["worker"]["environment"]["SEGUE_REDIS_URL"]
    assert url.startswith("rediss://")
    parsed = parse_url(url)  # exactly what redis-py makes of it
    assert parsed["connection_class"] is SSLConnection
    assert (parsed["host"], parsed["port"], parsed["password"]) == (
        env["STATE_HOST"],
        6380,
        env["REDIS_PASSWORD"],
    )
    assert parsed["ssl_ca_certs"] == "/tls/ca.crt"
    settings = Settings(redis_url=url)  # Segue's settings take it as it is, and never print it
    assert settings.redis_url == url and env["REDIS_PASSWORD"] not in repr(settings)


def test_minio_between_hosts_serves_https_with_the_state_hosts_certificate() -> None:
    minio = role("state")["minio"]
    assert "./tls/state.crt:/root/.minio/certs/public.crt:ro" in minio["volumes"]
    assert "./tls/state.key:/root/.minio/certs/private.key:ro" in minio["volumes"]
    assert "https://" in role("state")["bucket"]["command"][0]


def test_a_missing_secret_stops_compose() -> None:
    env = {k: v for k, v in hosts_env().items() if k != "REDIS_PASSWORD"}
    with pytest.raises(AssertionError, match="REDIS_PASSWORD"):
        compose(DEPLOY / "worker.compose.yml", env)


def test_the_image_installs_the_s3_extra() -> None:
    assert 'pip install --no-cache-dir ".[s3]"' in (REPO / "Dockerfile").read_text()
