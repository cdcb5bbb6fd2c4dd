"""Where durable bytes live: a local directory or an S3-compatible object store, behind one interface.

:func:`open_objects` picks the backend from ``SEGUE_STORE_URL`` (:class:`~workers.settings.Settings`):

* a path, or ``file:///path`` — :class:`LocalObjects`, one file per object under that directory
  (the default: ``./segue-data``, so the embedded setup needs nothing);
* ``s3://bucket/prefix`` — :class:`S3Objects`, any S3-compatible server. The endpoint and credentials
  come from the standard AWS variables (``AWS_ENDPOINT_URL`` for MinIO, Ceph or moto;
  ``AWS_ACCESS_KEY_ID``/``AWS_SECRET_ACCESS_KEY``; ``AWS_CA_BUNDLE`` for a private CA), read by
  boto3 itself, so a deployment configures Segue exactly as it configures the AWS CLI; the region
  is ``AWS_REGION`` (what the AWS SDKs and CLI v2 read, and what wins when both are set), else
  ``AWS_DEFAULT_REGION`` (:func:`s3_region`: botocore alone reads only the latter).

An object is named by a *key*, a ``/``-separated relative path of safe characters
(``clips/<sha256>.bvh``, ``databases/<id>/arrays/<name>.npy``). Semantics both backends keep:

* ``put`` replaces an object atomically: a reader sees the old bytes or the new, never a mix
  (local: a temporary file renamed into place; S3: a single PUT is atomic by the protocol);
* ``put(..., if_absent=True)`` is a conditional create: exactly one of two racing writers wins
  (local: ``os.link`` of a finished temporary file, which fails when the name exists; S3:
  ``If-None-Match: *``, answered 412 when the object exists);
* ``delete`` of a missing object is not an error; ``list`` is eventually complete on S3 (strongly
  consistent on AWS, MinIO and Ceph today).

Why boto3 (against obstore and fsspec/s3fs): it is the reference client every S3-compatible server
is tested against (MinIO, Ceph RGW, moto), it reads every standard AWS variable including
``AWS_ENDPOINT_URL`` without code of ours, it has the conditional writes this store needs
(``IfNoneMatch``, botocore >= 1.35), and it is a pure-Python wheel already present wherever moto is
(the tests' S3 server). obstore is faster for bulk parallel reads but is a native wheel we would add
for one call pattern the store does not have (its reads are whole small objects, or a database's
arrays downloaded once per worker); s3fs adds aiobotocore and an async layer for nothing we use.
The cost of boto3 is its size (botocore is about 30 MB unpacked), which is why it is the optional
``s3`` extra: ``pip install -e .`` (the local store) does not pull it in.
"""

from __future__ import annotations

import builtins
import contextlib
import os
import re
import shutil
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO, Protocol, cast
from urllib.parse import urlparse

from .storage_errors import StoreUnavailable as StoreUnavailable  # the API answers it with 507

STREAM_CHUNK = 1 << 20
"""Bytes read at once from a file stored by ``put_stream``."""

KEY_RE = re.compile(r"^[A-Za-z0-9_\-][A-Za-z0-9._\-]*(/[A-Za-z0-9_\-][A-Za-z0-9._\-]*)*$")
"""Object keys: relative, ``/``-separated, no empty, dot-led or ``..`` parts."""


class ObjectNotFound(LookupError):
    """No object under that key."""


def check_key(key: str) -> str:
    """``key`` when it is a valid object key, else ``ValueError``."""
    if not KEY_RE.match(key) or len(key) > 900:
        raise ValueError(f"invalid object key {key!r}")
    return key


class Objects(Protocol):
    """The operations the store needs of a backend (see the module docstring for the semantics)."""

    url: str

    def get(self, key: str) -> bytes:
        """The object's bytes; :class:`ObjectNotFound` when there is none."""
        ...

    def put(self, key: str, data: bytes, *, if_absent: bool = False) -> bool:
        """Store ``data`` under ``key`` (atomic replace); with ``if_absent``, only when no object
        has that key. True when written."""
        ...

    def put_stream(self, key: str, source: BinaryIO) -> None:
        """Store the bytes of the open file ``source`` (from its current position to its end)
        under ``key`` (atomic replace), read in chunks of :data:`STREAM_CHUNK` bytes: never held whole."""
        ...

    def delete(self, key: str) -> None:
        """Remove the object (nothing when there is none)."""
        ...

    def delete_prefix(self, prefix: str) -> None:
        """Remove every object whose key starts with ``prefix`` + ``/``."""
        ...

    def list(self, prefix: str) -> list[str]:
        """Keys directly or indirectly under ``prefix`` + ``/``, sorted."""
        ...

    def children(self, prefix: str) -> builtins.list[str]:
        """Names directly under ``prefix`` + ``/`` (the next key part: objects and sub-prefixes),
        sorted: one listing call however many objects lie deeper."""
        ...

    def exists(self, key: str) -> bool: ...

    def size(self, key: str) -> int:
        """The object's size in bytes; :class:`ObjectNotFound` when there is none."""
        ...

    def modified(self, key: str) -> float:
        """When the object was last written, Unix seconds; :class:`ObjectNotFound` when there is none."""
        ...

    def open(self, key: str) -> BinaryIO:
        """The object opened for reading in chunks (a file, or the server's response stream);
        :class:`ObjectNotFound` when there is none."""
        ...

    def download(self, key: str, path: Path) -> int:
        """Copy the object to the local file ``path`` (written whole, then renamed); its size."""
        ...

    def local_path(self, key: str) -> Path | None:
        """The object's own file when the backend is a local directory (read it in place, e.g.
        memory-map it), else None."""
        ...


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``path`` through a temporary file in its directory renamed into place."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


class LocalObjects:
    """Objects as files under ``root`` (the key is the relative path)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.url = str(self.root)

    def _path(self, key: str) -> Path:
        return self.root / check_key(key)

    def get(self, key: str) -> bytes:
        try:
            return self._path(key).read_bytes()
        except (FileNotFoundError, NotADirectoryError, IsADirectoryError):
            raise ObjectNotFound(key) from None

    def put(self, key: str, data: bytes, *, if_absent: bool = False) -> bool:
        path = self._path(key)
        if not if_absent:
            atomic_write(path, data)
            return True
        if path.exists():
            return False
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
            os.link(tmp, path)  # atomic create: fails when the name exists
            return True
        except FileExistsError:
            return False
        finally:
            Path(tmp).unlink(missing_ok=True)

    def put_stream(self, key: str, source: BinaryIO) -> None:
        path = self._path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                shutil.copyfileobj(source, fh, STREAM_CHUNK)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    def delete(self, key: str) -> None:
        with contextlib.suppress(FileNotFoundError, NotADirectoryError):
            self._path(key).unlink()

    def delete_prefix(self, prefix: str) -> None:
        shutil.rmtree(self._path(prefix), ignore_errors=True)

    def list(self, prefix: str) -> list[str]:
        base = self._path(prefix)
        if not base.is_dir():
            return []
        out = []
        for p in base.rglob("*"):
            if p.is_file() and not p.name.startswith("."):
                out.append(p.relative_to(self.root).as_posix())
        return sorted(out)

    def children(self, prefix: str) -> builtins.list[str]:
        base = self._path(prefix)
        if not base.is_dir():
            return []
        return sorted(p.name for p in base.iterdir() if not p.name.startswith("."))

    def exists(self, key: str) -> bool:
        return self._path(key).is_file()

    def size(self, key: str) -> int:
        try:
            return self._path(key).stat().st_size
        except (FileNotFoundError, NotADirectoryError):
            raise ObjectNotFound(key) from None

    def modified(self, key: str) -> float:
        try:
            return self._path(key).stat().st_mtime
        except (FileNotFoundError, NotADirectoryError):
            raise ObjectNotFound(key) from None

    def open(self, key: str) -> BinaryIO:
        try:
            return builtins.open(self._path(key), "rb")
        except (FileNotFoundError, NotADirectoryError, IsADirectoryError):
            raise ObjectNotFound(key) from None

    def download(self, key: str, path: Path) -> int:
        src = self._path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        os.close(fd)
        try:
            shutil.copyfile(src, tmp)
            os.replace(tmp, path)
        except FileNotFoundError:
            Path(tmp).unlink(missing_ok=True)
            raise ObjectNotFound(key) from None
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path.stat().st_size

    def local_path(self, key: str) -> Path | None:
        return self._path(key)


class S3Objects:
    """Objects in an S3 bucket under a key prefix, through boto3 (see the module docstring).

    One client per process (boto3 clients are thread-safe; a forked or spawned child makes its own
    through :func:`open_objects`)."""

    def __init__(self, bucket: str, prefix: str = "", client: Any = None) -> None:
        if not bucket:
            raise ValueError("an s3:// store URL needs a bucket: s3://bucket/prefix")
        self.bucket = bucket
        self.prefix = prefix.strip("/")
        self.url = f"s3://{bucket}/{self.prefix}" if self.prefix else f"s3://{bucket}"
        self._client = client
        self._lock = threading.Lock()
        self.read_timeout_s: float | None = None
        """botocore's socket read timeout (None: its 60 s); set before the first call to bound a
        call on a stalled server (the API sets ``SEGUE_STORE_TIMEOUT_S``)."""

    @property
    def client(self) -> Any:
        if self._client is None:
            with self._lock:
                if self._client is None:
                    try:
                        import boto3
                        from botocore.config import Config
                    except ImportError:
                        raise StoreUnavailable(
                            "an s3:// store needs boto3: pip install 'segue[s3]'"
                        ) from None
                    timeouts = {"read_timeout": self.read_timeout_s} if self.read_timeout_s else {}
                    config = Config(
                        retries={"max_attempts": 5, "mode": "standard"}, connect_timeout=5, **timeouts
                    )
                    self._client = boto3.client("s3", config=config, region_name=s3_region())
        return self._client

    def _key(self, key: str) -> str:
        check_key(key)
        return f"{self.prefix}/{key}" if self.prefix else key

    def _call(self, op: str, key: str, **kwargs: Any) -> Any:
        from botocore.exceptions import BotoCoreError, ClientError

        try:
            return getattr(self.client, op)(Bucket=self.bucket, **kwargs)
        except ClientError as exc:
            code = str(exc.response.get("Error", {}).get("Code", ""))
            status = exc.response.get("ResponseMetadata", {}).get("HTTPStatusCode")
            if code in ("NoSuchKey", "404", "NotFound") or status == 404:
                raise ObjectNotFound(key) from None
            if code in ("PreconditionFailed", "ConditionalRequestConflict") or status in (409, 412):
                raise FileExistsError(key) from None
            raise StoreUnavailable(f"object store {self.url}: {op} {key}: {code or exc}") from None
        except BotoCoreError as exc:
            raise StoreUnavailable(f"object store {self.url} unreachable: {exc}") from None

    def get(self, key: str) -> bytes:
        response = self._call("get_object", key, Key=self._key(key))
        return bytes(response["Body"].read())

    def get_tagged(self, key: str) -> tuple[bytes, str]:
        """The object's bytes and its ETag (for :meth:`put` ``if_match``: a compare-and-swap)."""
        response = self._call("get_object", key, Key=self._key(key))
        return bytes(response["Body"].read()), str(response["ETag"])

    def put(self, key: str, data: bytes, *, if_absent: bool = False, if_match: str | None = None) -> bool:
        """As :meth:`Objects.put`; with ``if_match``, only when the object's ETag is still that one
        (``If-Match``: False when another write came first)."""
        extra = {"IfNoneMatch": "*"} if if_absent else {"IfMatch": if_match} if if_match else {}
        try:
            self._call("put_object", key, Key=self._key(key), Body=data, **extra)
        except FileExistsError:
            return False
        except ObjectNotFound:  # If-Match on an object deleted meanwhile
            if if_match is None:
                raise
            return False
        return True

    def put_stream(self, key: str, source: BinaryIO) -> None:
        """One streamed ``PUT`` (botocore reads the file in chunks and seeks it back to retry)."""
        self._call("put_object", key, Key=self._key(key), Body=source)

    def delete(self, key: str) -> None:
        with contextlib.suppress(ObjectNotFound):
            self._call("delete_object", key, Key=self._key(key))

    def delete_prefix(self, prefix: str) -> None:
        keys = self.list(prefix)
        for start in range(0, len(keys), 1000):
            batch = [{"Key": self._key(k)} for k in keys[start : start + 1000]]
            self._call("delete_objects", prefix, Delete={"Objects": batch, "Quiet": True})

    def list(self, prefix: str) -> list[str]:
        full = self._key(prefix) + "/"
        strip = len(self.prefix) + 1 if self.prefix else 0
        out: list[str] = []
        token: str | None = None
        while True:
            extra = {"ContinuationToken": token} if token else {}
            page = self._call("list_objects_v2", prefix, Prefix=full, **extra)
            out.extend(str(item["Key"])[strip:] for item in page.get("Contents", []))
            if not page.get("IsTruncated"):
                return sorted(out)
            token = page.get("NextContinuationToken")

    def children(self, prefix: str) -> builtins.list[str]:
        full = self._key(prefix) + "/"
        out: set[str] = set()
        token: str | None = None
        while True:
            extra = {"ContinuationToken": token} if token else {}
            page = self._call("list_objects_v2", prefix, Prefix=full, Delimiter="/", **extra)
            out.update(str(p["Prefix"])[len(full) :].rstrip("/") for p in page.get("CommonPrefixes", []))
            out.update(str(item["Key"])[len(full) :] for item in page.get("Contents", []))
            if not page.get("IsTruncated"):
                return sorted(out)
            token = page.get("NextContinuationToken")

    def exists(self, key: str) -> bool:
        try:
            self.size(key)
        except ObjectNotFound:
            return False
        return True

    def size(self, key: str) -> int:
        return int(self._call("head_object", key, Key=self._key(key))["ContentLength"])

    def modified(self, key: str) -> float:
        return float(self._call("head_object", key, Key=self._key(key))["LastModified"].timestamp())

    def open(self, key: str) -> BinaryIO:
        body = self._call("get_object", key, Key=self._key(key))["Body"]
        return cast(BinaryIO, body)

    def download(self, key: str, path: Path) -> int:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                body = self._call("get_object", key, Key=self._key(key))["Body"]
                for chunk in iter(lambda: body.read(1 << 20), b""):
                    fh.write(chunk)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path.stat().st_size

    def local_path(self, key: str) -> Path | None:
        return None


def s3_region() -> str | None:
    """The region of the S3 client: ``AWS_REGION`` (the variable every AWS SDK and the AWS CLI v2
    read), else None, and boto3 reads ``AWS_DEFAULT_REGION`` or the profile's (botocore alone
    ignores ``AWS_REGION``)."""
    return os.environ.get("AWS_REGION") or None


def open_objects(url: str | Path) -> LocalObjects | S3Objects:
    """The backend a store URL names: ``s3://bucket/prefix``, ``file:///path`` or a plain path."""
    text = str(url)
    if text.startswith("s3://"):
        parsed = urlparse(text)
        return S3Objects(parsed.netloc, parsed.path)
    if text.startswith("file://"):
        return LocalObjects(urlparse(text).path)
    if "://" in text:
        raise ValueError(f"unsupported store URL {text!r}: use a directory or s3://bucket/prefix")
    return LocalObjects(text)


def iter_chunks(data: bytes, size: int) -> Iterator[bytes]:
    """``data`` in pieces of ``size`` bytes (the last one shorter)."""
    for start in range(0, len(data), size):
        yield data[start : start + size]
