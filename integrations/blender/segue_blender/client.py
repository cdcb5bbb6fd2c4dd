"""The Segue HTTP API with Python's standard library only (``http.client``, ``json``): what the
add-on needs of it, one persistent connection per thread.

Every method raises :class:`SegueError` for an error answer (the API's ``{"error": {"code",
"message"}}``) or when the server cannot be reached (``status`` 0, code ``unreachable``).
"""

from __future__ import annotations

import http.client
import json
import socket
import ssl
import threading
from collections.abc import Mapping
from typing import Any
from urllib.parse import quote, urlencode, urlsplit

USER_AGENT = "segue-blender"


class SegueError(Exception):
    """An error answer of the API, or an unreachable server (``status`` 0)."""

    def __init__(self, status: int, code: str, message: str, details: Any = None) -> None:
        super().__init__(f"{status} {code}: {message}" if status else message)
        self.status, self.code, self.message, self.details = status, code, message, details


def _error(status: int, body: bytes) -> SegueError:
    try:
        err = json.loads(body)["error"]
        return SegueError(status, str(err["code"]), str(err["message"]), err.get("details"))
    except (ValueError, KeyError, TypeError):
        return SegueError(status, f"http_{status}", body[:200].decode(errors="replace") or "no body")


Query = Mapping[str, str | int | float | bool | None]


class SegueClient:
    """One Segue server: ``url`` like ``http://127.0.0.1:8000``, ``token`` for servers with
    ``SEGUE_API_TOKENS``, ``timeout`` seconds for each request (a long poll adds its wait)."""

    def __init__(self, url: str, token: str | None = None, timeout: float = 30.0) -> None:
        parts = urlsplit(url.strip())
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise SegueError(0, "bad_url", f"not an http(s) URL: {url!r}")
        self.url = f"{parts.scheme}://{parts.netloc}{parts.path.rstrip('/')}"
        self.host = parts.hostname
        self.port = parts.port or (443 if parts.scheme == "https" else 80)
        self.https = parts.scheme == "https"
        self.prefix = parts.path.rstrip("/")
        self.token = token or None
        self.timeout = timeout
        self._local = threading.local()

    # -- plumbing ---------------------------------------------------------------------------------
    def _connection(self, timeout: float) -> http.client.HTTPConnection:
        conn: http.client.HTTPConnection | None = getattr(self._local, "conn", None)
        if conn is None:
            if self.https:
                conn = http.client.HTTPSConnection(
                    self.host, self.port, timeout=timeout, context=ssl.create_default_context()
                )
            else:
                conn = http.client.HTTPConnection(self.host, self.port, timeout=timeout)
            self._local.conn = conn
            self._local.used = False
        conn.timeout = timeout
        if conn.sock is not None:
            conn.sock.settimeout(timeout)
        return conn

    def close(self) -> None:
        """Close this thread's connection."""
        conn = getattr(self._local, "conn", None)
        if conn is not None:
            conn.close()
            self._local.conn = None

    def request(
        self,
        method: str,
        path: str,
        query: Query | None = None,
        body: bytes | None = None,
        content_type: str | None = None,
        timeout: float | None = None,
    ) -> bytes:
        """The body of a successful answer to ``method path?query`` (``SegueError`` otherwise)."""
        params = {
            k: ("true" if v is True else "false" if v is False else v) for k, v in (query or {}).items()
        }
        target = (
            self.prefix
            + path
            + ("?" + urlencode({k: v for k, v in params.items() if v is not None}) if params else "")
        )
        headers = {"User-Agent": USER_AGENT, "Accept": "application/json, */*"}
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        if body is not None:
            headers["Content-Type"] = content_type or "application/octet-stream"
        wait = self.timeout if timeout is None else timeout
        for attempt in (0, 1):
            conn = self._connection(wait)
            reused = bool(getattr(self._local, "used", False))
            try:
                conn.request(method, target, body=body, headers=headers)
                response = conn.getresponse()
                data = response.read()
                self._local.used = True
                if response.getheader("Connection", "").lower() == "close":
                    self.close()
            except (http.client.RemoteDisconnected, ConnectionResetError, BrokenPipeError) as exc:
                self.close()
                if reused and attempt == 0:
                    continue  # a kept-alive connection the server had closed: once more, anew
                raise SegueError(0, "unreachable", f"{self.url}: {exc}") from None
            except (OSError, http.client.HTTPException) as exc:
                self.close()
                what = "timed out" if isinstance(exc, socket.timeout) else str(exc) or type(exc).__name__
                raise SegueError(0, "unreachable", f"cannot reach Segue at {self.url}: {what}") from None
            if response.status >= 400:
                raise _error(response.status, data)
            return data
        raise AssertionError("unreachable")  # pragma: no cover

    def json(self, method: str, path: str, query: Query | None = None, payload: Any = None) -> Any:
        """A JSON answer; ``payload`` is sent as JSON when given."""
        body = None if payload is None else json.dumps(payload, allow_nan=False).encode()
        data = self.request(method, path, query, body, "application/json" if body is not None else None)
        return json.loads(data) if data else None

    # -- the API ----------------------------------------------------------------------------------
    def health(self) -> dict[str, Any]:
        """``/healthz`` (it answers 503 with a body when the backend cannot serve)."""
        try:
            data = self.request("GET", "/healthz", timeout=min(self.timeout, 10.0))
        except SegueError as exc:
            if exc.status == 503:
                return {"ok": False, "error": exc.message}
            raise
        return dict(json.loads(data))

    def clips(self) -> list[dict[str, Any]]:
        """The uploaded clips (``GET /v1/clips``)."""
        return list(self.json("GET", "/v1/clips"))

    def upload_clip(self, data: bytes, name: str, units: str | None = None) -> dict[str, Any]:
        """Upload a BVH (raw body, ``name`` its file name): the clip's info."""
        out = self.request(
            "POST", "/v1/clips", {"name": name, "units": units}, data, timeout=max(self.timeout, 120)
        )
        return dict(json.loads(out))

    def files(self) -> list[dict[str, Any]]:
        """The uploaded input files (``GET /v1/files``)."""
        return list(self.json("GET", "/v1/files"))

    def upload_file(self, data: bytes, name: str) -> dict[str, Any]:
        """Upload an input file (a character GLB, a recording, a MIDI song): its info."""
        out = self.request("POST", "/v1/files", {"name": name}, data, timeout=max(self.timeout, 120))
        return dict(json.loads(out))

    def databases(self) -> list[dict[str, Any]]:
        """Every database with its status (and ``summary`` when ready)."""
        return list(self.json("GET", "/v1/databases"))

    def database(self, db_id: str) -> dict[str, Any]:
        """One database."""
        return dict(self.json("GET", f"/v1/databases/{quote(db_id, safe='')}"))

    def build_database(self, spec: Mapping[str, Any]) -> dict[str, Any]:
        """Build (or find: content address) the database of ``spec``."""
        return dict(self.json("POST", "/v1/databases", payload=dict(spec)))

    def submit(self, request: Mapping[str, Any]) -> dict[str, Any]:
        """Submit a job request (its ``database`` set): the job's info."""
        return dict(self.json("POST", "/v1/jobs", payload=dict(request)))

    def job(self, job_id: str) -> dict[str, Any]:
        """A job's status."""
        return dict(self.json("GET", f"/v1/jobs/{quote(job_id, safe='')}"))

    def cancel(self, job_id: str) -> dict[str, Any]:
        """Ask a job to stop; it ends ``cancelled`` with its best result so far."""
        return dict(self.json("POST", f"/v1/jobs/{quote(job_id, safe='')}/cancel"))

    def events(self, job_id: str, after: int = 0, wait: float = 0.0) -> list[dict[str, Any]]:
        """The job's events after ``after``; with ``wait`` > 0 a long poll: the answer comes when
        the job ends or after ``wait`` seconds, with every event in between."""
        return list(
            self.json("GET", f"/v1/jobs/{quote(job_id, safe='')}/events", {"after": after, "wait": wait})
            if wait <= 0
            else json.loads(
                self.request(
                    "GET",
                    f"/v1/jobs/{quote(job_id, safe='')}/events",
                    {"after": after, "wait": wait},
                    timeout=self.timeout + wait,
                )
            )
        )

    def result(self, job_id: str, **params: str | int | float | bool | None) -> bytes:
        """A result download (``format``, ``result``, ``character``, ``animation_only``,
        ``dancer``, ``fps``... as ``GET /v1/jobs/{id}/result`` takes them)."""
        return self.request(
            "GET", f"/v1/jobs/{quote(job_id, safe='')}/result", params, timeout=max(self.timeout, 120)
        )

    def report(self, job_id: str, result: str | None = None) -> dict[str, Any]:
        """A result's report (constraint errors, plausibility, ``ok`` and ``reasons``)."""
        return dict(self.json("GET", f"/v1/jobs/{quote(job_id, safe='')}/report", {"result": result}))
