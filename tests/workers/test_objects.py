"""The object backends keep one contract: a local directory and a real S3-protocol server (moto)."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from workers.objects import LocalObjects, ObjectNotFound, Objects, S3Objects, open_objects


@pytest.fixture(params=["local", "s3"])
def objects(request: pytest.FixtureRequest, tmp_path: Path) -> Objects:
    if request.param == "local":
        return LocalObjects(tmp_path / "objects")
    s3 = open_objects(request.getfixturevalue("s3_url"))
    assert isinstance(s3, S3Objects)
    return s3


def test_put_get_list_delete(objects: Objects, tmp_path: Path) -> None:
    assert objects.list("jobs") == [] and not objects.exists("jobs/j1/info.json")
    with pytest.raises(ObjectNotFound):
        objects.get("jobs/j1/info.json")
    with pytest.raises(ObjectNotFound):
        objects.size("jobs/j1/info.json")
    objects.put("jobs/j1/info.json", b"one")
    objects.put("jobs/j1/results/r1.npz", b"\x00" * 1000)
    objects.put("jobs/j2/info.json", b"two")
    assert objects.get("jobs/j1/info.json") == b"one" and objects.size("jobs/j1/results/r1.npz") == 1000
    objects.put("jobs/j1/info.json", b"replaced")  # a whole replacement
    assert objects.get("jobs/j1/info.json") == b"replaced"
    assert objects.list("jobs") == ["jobs/j1/info.json", "jobs/j1/results/r1.npz", "jobs/j2/info.json"]
    assert objects.list("jobs/j1") == ["jobs/j1/info.json", "jobs/j1/results/r1.npz"]
    assert objects.children("jobs") == ["j1", "j2"] and objects.children("jobs/j1") == [
        "info.json",
        "results",
    ]
    assert objects.children("nothing") == []
    assert objects.download("jobs/j1/results/r1.npz", tmp_path / "dl" / "r1.npz") == 1000
    assert (tmp_path / "dl" / "r1.npz").read_bytes() == b"\x00" * 1000
    objects.delete_prefix("jobs/j1")
    assert objects.list("jobs") == ["jobs/j2/info.json"]
    objects.delete("jobs/j2/info.json")
    objects.delete("jobs/j2/info.json")  # deleting a missing object is no error
    assert objects.list("jobs") == []


def test_conditional_create_has_one_winner(objects: Objects) -> None:
    wins: list[bool] = []
    lock = threading.Lock()

    def writer(i: int) -> None:
        won = objects.put("clips/x.owners", f"writer {i}".encode(), if_absent=True)
        with lock:
            wins.append(won)

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert sorted(wins) == [False] * 7 + [True]
    assert objects.get("clips/x.owners").startswith(b"writer ")
    assert objects.put("clips/x.owners", b"forced") and objects.get("clips/x.owners") == b"forced"


@pytest.mark.parametrize("key", ["../x", "/abs", "a//b", ".hidden/x", "a/../b", ""])
def test_keys_cannot_escape(objects: Objects, key: str) -> None:
    with pytest.raises(ValueError, match="invalid object key"):
        objects.put(key, b"x")


def test_store_urls() -> None:
    s3 = open_objects("s3://bucket/some/prefix/")
    assert isinstance(s3, S3Objects) and (s3.bucket, s3.prefix) == ("bucket", "some/prefix")
    assert s3.url == "s3://bucket/some/prefix" and s3.local_path("x") is None
    with pytest.raises(ValueError, match="unsupported store URL"):
        open_objects("gs://bucket")
    with pytest.raises(ValueError, match="needs a bucket"):
        open_objects("s3:///prefix")


def test_unreachable_store_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    from workers.objects import StoreUnavailable

    monkeypatch.setenv("AWS_ENDPOINT_URL", "http://127.0.0.1:9")  # nothing listens there
    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "x")
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", "x")
    monkeypatch.setenv("AWS_DEFAULT_REGION", "us-east-1")
    store = open_objects("s3://nowhere/p")
    assert isinstance(store, S3Objects)
    import boto3
    from botocore.config import Config

    store._client = boto3.client("s3", config=Config(retries={"max_attempts": 1}, connect_timeout=1))
    with pytest.raises(StoreUnavailable, match="unreachable"):
        store.get("clips/a.json")


def test_aws_region_is_the_s3_clients_region(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """``AWS_REGION`` (what the AWS SDKs and CLI v2 read) names the region, and wins over
    ``AWS_DEFAULT_REGION`` when both are set; botocore alone read only the latter."""
    pytest.importorskip("boto3")
    monkeypatch.setenv("AWS_CONFIG_FILE", str(tmp_path / "none"))  # no profile's region
    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "k")
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", "s")
    monkeypatch.delenv("AWS_DEFAULT_REGION", raising=False)
    monkeypatch.setenv("AWS_REGION", "eu-west-3")
    assert S3Objects("bucket").client.meta.region_name == "eu-west-3"
    monkeypatch.setenv("AWS_DEFAULT_REGION", "us-west-2")
    assert S3Objects("bucket").client.meta.region_name == "eu-west-3"
    monkeypatch.delenv("AWS_REGION")
    assert S3Objects("bucket").client.meta.region_name == "us-west-2"


def test_put_stream_stores_a_file_in_chunks(objects: Objects, tmp_path: Path) -> None:
    """An upload spooled to disk is stored from its file (several chunks, replacing atomically)."""
    import os

    from workers.objects import STREAM_CHUNK

    data = os.urandom(2 * STREAM_CHUNK + 123)
    spooled = tmp_path / "spooled"
    spooled.write_bytes(data)
    with spooled.open("rb") as fh:
        objects.put_stream("files/big.bin", fh)
    assert objects.get("files/big.bin") == data and objects.size("files/big.bin") == len(data)
    with spooled.open("rb") as fh:
        fh.seek(len(data) - 10)  # from the file's current position
        objects.put_stream("files/big.bin", fh)
    assert objects.get("files/big.bin") == data[-10:]
