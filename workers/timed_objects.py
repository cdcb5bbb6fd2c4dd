"""Store calls with a time limit: :class:`TimedObjects` wraps an :class:`~workers.objects.Objects`
backend so that no call waits on a stalled store longer than ``SEGUE_STORE_TIMEOUT_S``.

Each call runs on a small thread pool of its own and the caller waits at most the limit
(:data:`STREAM_FACTOR` times it for a streamed upload or a download, which move many megabytes);
past it the caller gets :class:`~workers.storage_errors.StoreTimeout` (the API answers 503
``store_unavailable`` with ``Retry-After``) while the stalled call is left to finish or fail on its
own thread. A call still queued behind stalled ones is cancelled when its caller gives up, so a
stall occupies at most :data:`THREADS` threads, and every later caller is answered within the
limit instead of piling up. This covers every backend alike (a local directory on a hung network
mount as well as an object store; an S3 client's own socket timeouts end its stalled calls too).

The API process wraps its store so (:func:`service.app.lifespan`); the workers do not (a worker's
job has its own time limits, and its supervisor stops it).
"""

from __future__ import annotations

import builtins
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from pathlib import Path
from typing import Any, BinaryIO, TypeVar

from .objects import Objects
from .storage_errors import StoreTimeout

T = TypeVar("T")

THREADS = 32
"""Store calls running at once in one process (the callers beyond wait, within their limit)."""
STREAM_FACTOR = 10
"""A streamed upload's or a download's limit, in multiples of the call limit."""


class TimedObjects:
    """``inner`` with every call bounded by ``timeout_s`` seconds (module docstring). Attributes
    other than the :class:`~workers.objects.Objects` calls (``root``, ``bucket``...) are the
    inner backend's; its other calls (``get_tagged``) are bounded too."""

    def __init__(self, inner: Objects, timeout_s: float, threads: int = THREADS) -> None:
        if timeout_s <= 0:
            raise ValueError(f"a store timeout must be positive, not {timeout_s}")
        self.inner = inner
        self.url = inner.url
        self.timeout_s = timeout_s
        self._pool = ThreadPoolExecutor(threads, thread_name_prefix="store-call")

    def _call(
        self, op: str, fn: Callable[..., T], *args: Any, limit: float | None = None, **kwargs: Any
    ) -> T:
        seconds = self.timeout_s if limit is None else limit
        future = self._pool.submit(fn, *args, **kwargs)
        try:
            return future.result(timeout=seconds)
        except FutureTimeout:
            future.cancel()  # not started yet (queued behind stalled calls): it never runs
            raise StoreTimeout(
                f"the store {self.url} did not answer {op} in {seconds:g} s (SEGUE_STORE_TIMEOUT_S)"
            ) from None

    def __getattr__(self, name: str) -> Any:
        value = getattr(self.inner, name)
        if not callable(value):
            return value

        def timed(*args: Any, **kwargs: Any) -> Any:
            return self._call(name, value, *args, **kwargs)

        return timed

    def close(self) -> None:
        """Stop the call threads (those stalled end when their call does)."""
        self._pool.shutdown(wait=False, cancel_futures=True)

    def get(self, key: str) -> bytes:
        return self._call("get", self.inner.get, key)

    def put(self, key: str, data: bytes, *, if_absent: bool = False, **extra: Any) -> bool:
        put: Callable[..., bool] = self.inner.put
        return self._call("put", put, key, data, if_absent=if_absent, **extra)

    def put_stream(self, key: str, source: BinaryIO) -> None:
        limit = self.timeout_s * STREAM_FACTOR
        self._call("put_stream", self.inner.put_stream, key, source, limit=limit)

    def delete(self, key: str) -> None:
        self._call("delete", self.inner.delete, key)

    def delete_prefix(self, prefix: str) -> None:
        self._call("delete_prefix", self.inner.delete_prefix, prefix)

    def list(self, prefix: str) -> builtins.list[str]:
        return self._call("list", self.inner.list, prefix)

    def children(self, prefix: str) -> builtins.list[str]:
        return self._call("children", self.inner.children, prefix)

    def exists(self, key: str) -> bool:
        return self._call("exists", self.inner.exists, key)

    def size(self, key: str) -> int:
        return self._call("size", self.inner.size, key)

    def modified(self, key: str) -> float:
        return self._call("modified", self.inner.modified, key)

    def open(self, key: str) -> BinaryIO:
        return self._call("open", self.inner.open, key)

    def download(self, key: str, path: Path) -> int:
        limit = self.timeout_s * STREAM_FACTOR
        return self._call("download", self.inner.download, key, path, limit=limit)

    def local_path(self, key: str) -> Path | None:
        return self.inner.local_path(key)  # no I/O: a path under the store's directory


def untimed(objects: Objects) -> Objects:
    """The backend under a :class:`TimedObjects` (``objects`` itself otherwise): what a caller that
    picks its protocol by the backend's kind inspects (:mod:`workers.holders`)."""
    return objects.inner if isinstance(objects, TimedObjects) else objects
