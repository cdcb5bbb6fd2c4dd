"""Storage failures are clear: on a really full file system (a 4 MiB tmpfs mounted for the test) a
write answers 507 ``storage_full`` with a message and stores nothing, DELETE still works (space is
freed through the API), and once there is room again writes succeed."""

from __future__ import annotations

import errno
import gzip
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import pytest
from fastapi.testclient import TestClient

from motion.samples import sample_path
from service.app import create_app
from service.settings import Settings
from workers.storage_errors import StoreUnavailable, storage_problem

from .conftest import PLUGINS, REPO


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 4 MiB tmpfs (needs root, or CAP_SYS_ADMIN, as in the project's containers)."""
    mount = tmp_path / "disk"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(mount)], capture_output=True, text=True
    )
    if done.returncode != 0:
        reason = f"cannot mount a tmpfs here ({done.stderr.strip() or done.returncode})"
        if os.environ.get("CI") == "true":
            pytest.fail(reason)
        pytest.skip(reason)
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


def fill(path: Path) -> None:
    """Write zeros to ``path`` until the file system is full (a real ENOSPC)."""

    def write_until_full(fh: BinaryIO, size: int) -> None:
        while True:
            fh.write(b"\0" * size)

    with path.open("wb", buffering=0) as fh:
        for size in (65536, 512):  # big blocks, then the last bytes a few at a time
            with pytest.raises(OSError, match="No space left") as full:
                write_until_full(fh, size)
            assert full.value.errno == errno.ENOSPC


def test_full_disk_is_507_and_delete_frees_space(small_disk: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    # a principal that is not an admin: its delete drops its hold, which used to rewrite a file
    settings = Settings(
        data_dir=small_disk / "data", workers=1, engine_plugins=PLUGINS, api_tokens=("alice:s3cret",)
    )
    walk = sample_path("walk").read_bytes()
    text = gzip.decompress(walk)  # other bytes, the same clip
    auth = {"Authorization": "Bearer s3cret"}
    with TestClient(create_app(settings), base_url="http://localhost", headers=auth) as client:
        first = client.post("/v1/clips", files={"file": ("walk.bvh.gz", walk)})
        assert first.status_code == 201, first.text
        filler = small_disk / "filler"
        fill(filler)
        other = client.post("/v1/clips", files={"file": ("walk2.bvh", text)})
        assert other.status_code == 507, other.text
        body = other.json()["error"]
        assert body["code"] == "storage_full" and "ENOSPC" in body["message"]
        assert "DELETE" in body["message"] and other.headers["Retry-After"]
        assert [c["id"] for c in client.get("/v1/clips").json()] == [first.json()["id"]]
        # the disk is still full: the delete works and frees the clip's bytes
        assert client.delete(f"/v1/clips/{first.json()['id']}").status_code == 204
        assert client.get("/v1/clips").json() == []
        filler.unlink()
        again = client.post("/v1/clips", files={"file": ("walk2.bvh", text)})
        assert again.status_code == 201, again.text


def test_storage_problems_are_named() -> None:
    assert storage_problem(OSError(errno.EDQUOT, "quota"))[0] == "storage_full"  # type: ignore[index]
    assert storage_problem(OSError(errno.EROFS, "ro"))[0] == "storage_read_only"  # type: ignore[index]
    assert storage_problem(StoreUnavailable("no answer"))[0] == "storage_unavailable"  # type: ignore[index]
    wrapped = RuntimeError("wrapped")
    wrapped.__cause__ = OSError(errno.EIO, "I/O error")
    assert storage_problem(wrapped) == (
        "storage_unavailable",
        "the server's storage cannot be reached (EIO); try again later",
    )
    assert storage_problem(FileNotFoundError(errno.ENOENT, "x")) is None
    assert storage_problem(ValueError("x")) is None
