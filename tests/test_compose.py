"""docker-compose.yml's shape, checked by parsing it (no Docker daemon is needed, none is used):
an API, two workers, Redis, MinIO and a one-shot bucket creation; no volume shared by Segue's
processes (each container's disk is a cache only); every Segue process on the same object store."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from workers.objects import S3Objects, open_objects

REPO = Path(__file__).resolve().parents[1]


def _compose() -> dict[str, Any]:
    return dict(yaml.safe_load((REPO / "docker-compose.yml").read_text()))


def test_services_are_the_api_two_workers_redis_minio_and_the_bucket() -> None:
    services = _compose()["services"]
    assert set(services) == {"api", "worker", "redis", "minio", "bucket"}
    assert services["worker"]["deploy"]["replicas"] == 2
    assert services["api"]["command"][:2] == ["segue", "serve"]
    assert services["worker"]["command"][:2] == ["segue", "worker"]
    assert services["minio"]["image"].startswith("minio/minio")
    assert services["bucket"]["image"].startswith("minio/mc")
    for name in ("api", "worker"):
        assert services[name]["depends_on"]["bucket"] == {"condition": "service_completed_successfully"}
        assert "redis://redis:6379/0" in services[name]["command"]


def test_no_volume_is_shared_and_segue_processes_mount_none() -> None:
    compose = _compose()
    services = compose["services"]
    for name in ("api", "worker", "redis", "bucket"):
        assert "volumes" not in services[name], f"{name} mounts a volume: its disk must be a cache only"
    mounts = [v.split(":")[0] for s in services.values() for v in s.get("volumes", [])]
    assert len(mounts) == len(set(mounts)) == 1  # MinIO's own disk, nobody else's
    assert set(compose.get("volumes", {})) == set(mounts)


def test_api_and_workers_use_the_same_store_and_the_bucket_service_creates_it() -> None:
    services = _compose()["services"]
    store_keys = ("SEGUE_STORE_URL", "AWS_ENDPOINT_URL", "AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY")
    envs = [services[name]["environment"] for name in ("api", "worker")]
    for key in store_keys:
        assert envs[0][key] == envs[1][key], key
    env = envs[0]
    objects = open_objects(env["SEGUE_STORE_URL"])
    assert isinstance(objects, S3Objects)
    bucket = objects.bucket
    minio = services["minio"]["environment"]
    assert (minio["MINIO_ROOT_USER"], minio["MINIO_ROOT_PASSWORD"]) == (
        env["AWS_ACCESS_KEY_ID"],
        env["AWS_SECRET_ACCESS_KEY"],
    )
    assert env["AWS_ENDPOINT_URL"] == "http://minio:9000"
    script = " ".join(services["bucket"]["command"])
    assert f"store/{bucket}" in script and "http://minio:9000" in script
    assert env["AWS_SECRET_ACCESS_KEY"] in script


def test_the_image_installs_the_s3_extra() -> None:
    assert 'pip install --no-cache-dir ".[s3]"' in (REPO / "Dockerfile").read_text()
