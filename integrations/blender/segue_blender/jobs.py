"""A job followed in a background thread: submission, its events (long polls of
``/v1/jobs/{id}/events``), each new best result downloaded as it arrives, and the report; what
happens is put on a queue the UI drains (Blender's data is touched only in the main thread).

Messages (``Message.kind``): ``submitted`` (the job's info), ``solution`` (a result id, its
event data and what :func:`prepare` made of its download), ``report`` (a result's report),
``end`` (the terminal event: ``done``, ``cancelled`` or ``failed``), ``error`` (a message).
Solutions that arrive while a download runs are skipped for the newest one.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from .client import SegueClient, SegueError

POLL_WAIT_S = 0.25
"""Each long poll's wait: the events endpoint answers when the job ends or after this long, so a
solution is seen this long after it is published at most."""
TERMINAL = ("done", "cancelled", "failed")


@dataclass(slots=True)
class Message:
    kind: str
    data: dict[str, Any] = field(default_factory=dict)
    prepared: Any = None
    at: float = field(default_factory=time.perf_counter)


class JobRunner(threading.Thread):
    """Submit ``request`` (or follow ``job_id``) and follow it to its end.

    Parameters
    ----------
    client:
        The server.
    request:
        A job request (``database`` set), built in this thread by ``build()`` when a callable
        (uploads and the database's summary come first), or None to follow ``job_id``.
    download:
        Result id -> the bytes to show (e.g. the bound GLB); None: no downloads.
    prepare:
        Those bytes -> what the UI needs (parsing, in this thread).
    """

    def __init__(
        self,
        client: SegueClient,
        request: Mapping[str, Any] | Callable[[], Mapping[str, Any]] | None,
        download: Callable[[str], bytes] | None = None,
        prepare: Callable[[bytes], Any] | None = None,
        job_id: str | None = None,
    ) -> None:
        super().__init__(name="segue-job", daemon=True)
        self.client = client
        self.request = request
        self.download = download
        self.prepare = prepare
        self.job_id = job_id
        self.messages: queue.Queue[Message] = queue.Queue()
        self._cancel_asked = threading.Event()
        self._abandoned = threading.Event()
        self.best: str | None = None
        self.shown: str | None = None

    def cancel(self) -> None:
        """Ask the job to stop (it ends ``cancelled`` keeping the best so far)."""
        self._cancel_asked.set()

    def abandon(self) -> None:
        """Stop following (the job goes on on the server)."""
        self._abandoned.set()

    def run(self) -> None:
        try:
            self._run()
        except SegueError as exc:
            self.messages.put(
                Message("error", {"message": exc.message, "code": exc.code, "status": exc.status})
            )
        except Exception as exc:  # the UI must hear of any failure
            self.messages.put(
                Message("error", {"message": f"{type(exc).__name__}: {exc}", "code": "internal"})
            )

    def _show(self, rid: str, data: dict[str, Any], seen: float) -> None:
        if self.download is None:
            return
        data = {**data, "seen_at": seen}
        raw = self.download(rid)
        prepared = self.prepare(raw) if self.prepare is not None else raw
        self.shown = rid
        self.messages.put(Message("solution", {"result": rid, **data}, prepared))
        self.messages.put(
            Message("report", {"result": rid, "report": self.client.report(self.job_id or "", rid)})
        )

    def _run(self) -> None:
        if self.job_id is None:
            req = self.request() if callable(self.request) else self.request
            if req is None:
                raise SegueError(0, "no_request", "nothing to submit")
            info = self.client.submit(req)
            self.job_id = str(info["id"])
            self.messages.put(Message("submitted", dict(info)))
        after, ended, cancel_sent = 0, None, False
        pending: tuple[str, dict[str, Any], float] | None = None
        while not self._abandoned.is_set():
            if self._cancel_asked.is_set() and not cancel_sent:
                self.client.cancel(self.job_id)
                cancel_sent = True
            events = self.client.events(self.job_id, after, POLL_WAIT_S if pending is None else 0.0)
            for ev in events:
                after = max(after, int(ev["id"]))
                kind, data = str(ev["type"]), dict(ev.get("data") or {})
                if kind == "solution" and data.get("result"):
                    self.best = str(data["result"])
                    pending = (self.best, data, time.perf_counter())
                elif kind in TERMINAL:
                    ended = (kind, data)
                    if data.get("result"):
                        best = str(data["result"])
                        if best != self.shown and (pending is None or pending[0] != best):
                            pending = (best, data, time.perf_counter())
                        self.best = best
                elif kind == "started":
                    self.messages.put(Message("started", data))
            if pending is not None and not self._abandoned.is_set():
                rid, data, seen = pending
                pending = None
                if rid != self.shown:
                    self._show(rid, data, seen)
                continue  # look for newer events before waiting again
            if ended is not None:
                kind, data = ended
                self.messages.put(Message("end", {"type": kind, **data}))
                return
