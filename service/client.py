"""A small synchronous client for the Segue HTTP/WebSocket API (httpx + ``websockets.sync``).

Example
-------
>>> from service.client import SegueClient                                    # doctest: +SKIP
>>> with SegueClient("http://127.0.0.1:8000") as segue:                       # doctest: +SKIP
...     clip = segue.upload_clip("07_01_walk_daz.bvh.gz")
...     db = segue.build_database({"kind": "clips", "clips": [{"bvh": clip.name}], "fps": 30})
...     job = segue.submit({"engine": "clip", "database": db.id, "clip": "07_01_walk_daz", "end": 60})
...     for event in segue.events(job.id):
...         print(event.id, event.type.value, event.data)
...     segue.result(job.id, "glb", "walk.glb")
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any
from urllib.parse import urlencode

import httpx
from pydantic import BaseModel
from websockets.exceptions import ConnectionClosedError, InvalidStatus
from websockets.sync.client import ClientConnection, connect

from schemas import ClipInfo, DatabaseInfo, DatabaseStatus, JobEvent, JobInfo, Report
from schemas.files import FileInfo
from schemas.movement_graph import GraphEdits, MovementGraph


class SegueError(Exception):
    """An error answer of the API (``status`` is the HTTP status, or 4xx/1011 for WebSocket closes)."""

    def __init__(self, status: int, code: str, message: str, details: Any = None) -> None:
        super().__init__(f"{status} {code}: {message}")
        self.status = status
        self.code = code
        self.message = message
        self.details = details


def _error_from(status: int, body: bytes) -> SegueError:
    try:
        err = json.loads(body)["error"]
        return SegueError(status, str(err["code"]), str(err["message"]), err.get("details"))
    except (ValueError, KeyError, TypeError):
        return SegueError(status, f"http_{status}", body[:200].decode(errors="replace") or "no body")


_WS_CLOSE_STATUS = {4401: 401, 4404: 404}

DEFAULT_URL = "http://127.0.0.1:8000"
"""Where ``segue serve`` listens by default."""


class SegueClient:
    """The API of one Segue server.

    Parameters
    ----------
    base_url:
        e.g. ``"http://127.0.0.1:8000"``; default: ``$SEGUE_URL``, else :data:`DEFAULT_URL`.
    token:
        Bearer token for servers with ``SEGUE_API_TOKENS`` (writes and WebSockets).
    timeout:
        Seconds for each HTTP request.
    """

    def __init__(self, base_url: str | None = None, token: str | None = None, timeout: float = 60.0) -> None:
        self.base_url = (base_url or os.environ.get("SEGUE_URL") or DEFAULT_URL).rstrip("/")
        self.token = token
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.http = httpx.Client(base_url=self.base_url, headers=headers, timeout=timeout)

    # -- plumbing -------------------------------------------------------------------------------
    def close(self) -> None:
        """Close the HTTP connection pool."""
        self.http.close()

    def __enter__(self) -> SegueClient:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def _request(self, method: str, path: str, **kwargs: Any) -> httpx.Response:
        response = self.http.request(method, path, **kwargs)
        if response.status_code >= 400:
            raise _error_from(response.status_code, response.content)
        return response

    @staticmethod
    def _json(value: dict[str, Any] | BaseModel) -> dict[str, Any]:
        return value.model_dump(mode="json", exclude_none=True) if isinstance(value, BaseModel) else value

    def _ws(self, path: str) -> ClientConnection:
        url = "ws" + self.base_url.removeprefix("http") + path
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else None
        try:
            return connect(url, additional_headers=headers, open_timeout=10, max_size=None)
        except InvalidStatus as exc:
            raise _error_from(exc.response.status_code, exc.response.body or b"") from None

    # -- clips ----------------------------------------------------------------------------------
    def upload_clip(self, path: str | Path, name: str | None = None, units: str | None = None) -> ClipInfo:
        """Upload a ``.bvh``/``.bvh.gz`` file (named by its file name unless ``name``)."""
        p = Path(path)
        params = {"units": units} if units else {}
        with p.open("rb") as fh:
            files = {"file": (name or p.name, fh, "application/octet-stream")}
            return ClipInfo.model_validate(
                self._request("POST", "/v1/clips", files=files, params=params).json()
            )

    def clips(self) -> list[ClipInfo]:
        """Every uploaded clip."""
        return [ClipInfo.model_validate(c) for c in self._request("GET", "/v1/clips").json()]

    def delete_clip(self, clip_id: str) -> None:
        """Delete an uploaded clip."""
        self._request("DELETE", f"/v1/clips/{clip_id}")

    # -- other input files ----------------------------------------------------------------------
    def upload_file(self, path: str | Path, name: str | None = None) -> FileInfo:
        """Upload an input file of requests (e.g. a MIDI song); requests name it by file name or id."""
        p = Path(path)
        with p.open("rb") as fh:
            files = {"file": (name or p.name, fh, "application/octet-stream")}
            return FileInfo.model_validate(self._request("POST", "/v1/files", files=files).json())

    # -- databases ------------------------------------------------------------------------------
    def build_database(
        self, spec: dict[str, Any] | BaseModel, wait: bool = True, timeout: float = 600.0
    ) -> DatabaseInfo:
        """Build (or find) the database of ``spec``; with ``wait``, return once it is ready.

        Raises :class:`SegueError` when the build fails (code ``build_failed``).
        """
        info = DatabaseInfo.model_validate(
            self._request("POST", "/v1/databases", json=self._json(spec)).json()
        )
        if not wait or info.status == DatabaseStatus.ready:
            return info
        deadline = time.monotonic() + timeout
        if info.build_job is not None:
            for _ in self.events(info.build_job):
                if time.monotonic() > deadline:
                    break
        while True:
            info = self.database(info.id)
            if info.status == DatabaseStatus.ready:
                return info
            if info.status == DatabaseStatus.failed:
                raise SegueError(422, "build_failed", f"database {info.id} failed to build: {info.error}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"database {info.id} is still {info.status.value} after {timeout} s")
            time.sleep(0.1)

    def database(self, db_id: str) -> DatabaseInfo:
        """One database's status."""
        return DatabaseInfo.model_validate(self._request("GET", f"/v1/databases/{db_id}").json())

    def delete_database(self, db_id: str) -> None:
        """Delete a database."""
        self._request("DELETE", f"/v1/databases/{db_id}")

    def graph(self, db_id: str) -> MovementGraph:
        """A rhythm database's movement transition graph (groups and transitions)."""
        return MovementGraph.model_validate(self._request("GET", f"/v1/databases/{db_id}/graph").json())

    def edit_graph(self, db_id: str, edits: list[dict[str, Any]] | GraphEdits) -> DatabaseInfo:
        """The database derived from a rhythm database by movement-graph edits (connect, cut,
        weight; see the OpenAPI ``GraphEdits`` schema). Raises :class:`SegueError` (422) naming the
        edit that breaks a rule."""
        body = edits.model_dump(mode="json") if isinstance(edits, GraphEdits) else {"edits": edits}
        r = self._request("POST", f"/v1/databases/{db_id}/graph-edits", json=body)
        return DatabaseInfo.model_validate(r.json())

    # -- jobs -----------------------------------------------------------------------------------
    def submit(self, request: dict[str, Any] | BaseModel) -> JobInfo:
        """Submit a job request (see the OpenAPI ``JobRequest`` schema)."""
        return JobInfo.model_validate(self._request("POST", "/v1/jobs", json=self._json(request)).json())

    def job(self, job_id: str) -> JobInfo:
        """A job's status."""
        return JobInfo.model_validate(self._request("GET", f"/v1/jobs/{job_id}").json())

    def cancel(self, job_id: str) -> JobInfo:
        """Ask a job to stop (it ends ``cancelled`` with its best result so far)."""
        return JobInfo.model_validate(self._request("POST", f"/v1/jobs/{job_id}/cancel").json())

    def delete_job(self, job_id: str) -> None:
        """Delete a finished job with its events and results (:class:`SegueError` 409
        ``job_not_finished`` while it is queued or running: cancel it first)."""
        self._request("DELETE", f"/v1/jobs/{job_id}")

    def events(self, job_id: str, after: int = 0, reconnects: int = 3) -> Iterator[JobEvent]:
        """A job's events over the WebSocket, until the terminal one (``done``/``failed``/``cancelled``).

        A dropped connection is resumed with ``after=<last id seen>`` (up to ``reconnects`` times in a row).
        """
        last, failures = after, 0
        while True:
            try:
                with self._ws(f"/v1/jobs/{job_id}/events?{urlencode({'after': last})}") as ws:
                    for message in ws:
                        event = JobEvent.model_validate_json(message)
                        last, failures = event.id, 0
                        yield event
                        if event.type.terminal:
                            return
                    return  # closed normally after the job's end (nothing after ``last``)
            except ConnectionClosedError as exc:
                code = exc.rcvd.code if exc.rcvd is not None else 1006
                reason = exc.rcvd.reason if exc.rcvd is not None else "connection lost"
                if code in _WS_CLOSE_STATUS:
                    raise SegueError(_WS_CLOSE_STATUS[code], "websocket_closed", reason) from None
                failures += 1
                if failures > reconnects:
                    raise SegueError(code, "websocket_closed", reason) from None
                time.sleep(0.1 * failures)
            except (ConnectionError, TimeoutError) as exc:
                failures += 1
                if failures > reconnects:
                    raise SegueError(503, "unreachable", str(exc)) from None
                time.sleep(0.1 * failures)

    def poll_events(self, job_id: str, after: int = 0, wait: float = 0.0) -> list[JobEvent]:
        """The events after ``after`` over plain HTTP: those there now, or with ``wait`` > 0 every
        event until the job ends or ``wait`` seconds pass (a long poll)."""
        params = {"after": after, "wait": wait}
        return [
            JobEvent.model_validate(e)
            for e in self._request("GET", f"/v1/jobs/{job_id}/events", params=params).json()
        ]

    def result(
        self,
        job_id: str,
        format: str = "bvh",
        path: str | Path | None = None,
        result: str | None = None,
        target: str = "gltf",
        character: str | None = None,
        feet: str | None = None,
    ) -> bytes:
        """A result motion as ``bvh``, ``glb``, ``json`` or ``npz`` bytes (also written to ``path``);
        ``character``: an uploaded clip or file id to retarget it onto (docs/retargeting.md);
        ``feet``: ``lock``, ``grounding`` or ``free`` (the server's default: lock on a character,
        free without)."""
        params = {"format": format, "target": target} | ({"result": result} if result else {})
        params |= {"character": character} if character else {}
        params |= {"feet": feet} if feet else {}
        data = self._request("GET", f"/v1/jobs/{job_id}/result", params=params).content
        if path is not None:
            Path(path).write_bytes(data)
        return data

    def report(self, job_id: str, result: str | None = None) -> Report:
        """A result's report (score terms, metrics, provenance)."""
        params = {"result": result} if result else {}
        return Report.model_validate(self._request("GET", f"/v1/jobs/{job_id}/report", params=params).json())

    def health(self) -> dict[str, Any]:
        """``/healthz``."""
        return dict(self.http.get("/healthz").json())
