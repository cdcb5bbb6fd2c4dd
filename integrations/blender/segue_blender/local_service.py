"""A local Segue service started from the add-on: ``segue serve`` on a free 127.0.0.1 port, from
the ``segue`` executable of a venv where Segue is installed, stopped when Blender exits (or when
asked). Plain Python (``subprocess``), no Blender."""

from __future__ import annotations

import atexit
import os
import socket
import subprocess
import time
from collections.abc import Sequence
from pathlib import Path

from .client import SegueClient, SegueError

START_TIMEOUT_S = 120.0
"""How long a starting server may take to answer ``/healthz`` (a guard, not a pace: a loaded
machine imports the service slowly)."""


def free_port() -> int:
    """A TCP port nothing listens on now (127.0.0.1)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class LocalService:
    """One ``segue serve`` child process.

    Parameters
    ----------
    executable:
        The ``segue`` program (e.g. ``~/venvs/segue/bin/segue``).
    data_dir:
        Its data directory (clips, databases, results).
    imports:
        Database folders ``segue build`` wrote, served by it (``--import DIR``).
    """

    def __init__(
        self, executable: str | Path, data_dir: str | Path, imports: Sequence[str | Path] = ()
    ) -> None:
        self.executable = Path(executable).expanduser()
        self.data_dir = Path(data_dir).expanduser()
        self.imports = [Path(d).expanduser() for d in imports]
        self.process: subprocess.Popen[bytes] | None = None
        self.url = ""
        self.log_path = self.data_dir / "segue-serve.log"

    @property
    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def start(self, timeout: float = START_TIMEOUT_S) -> str:
        """Start it and wait until it answers; its URL. ``SegueError`` (code ``local_service``)
        naming the problem (no such executable, it exited: the end of its log)."""
        if self.running:
            return self.url
        if not self.executable.is_file() or not os.access(self.executable, os.X_OK):
            raise SegueError(0, "local_service", f"no segue executable at {self.executable}")
        for d in self.imports:
            if not (d / "info.json").is_file():
                raise SegueError(0, "local_service", f"{d} is not a database folder `segue build` wrote")
        self.data_dir.mkdir(parents=True, exist_ok=True)
        port = free_port()
        args = [str(self.executable), "serve", "--port", str(port), "--data", str(self.data_dir),
                "--log-level", "warning"]  # fmt: skip
        for d in self.imports:
            args += ["--import", str(d)]
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
        with self.log_path.open("ab") as log:
            self.process = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, env=env,
                                            start_new_session=True)  # fmt: skip
        _STARTED.append(self)
        self.url = f"http://127.0.0.1:{port}"
        client = SegueClient(self.url, timeout=2.0)
        deadline = time.monotonic() + timeout
        try:
            while True:
                if self.process.poll() is not None:
                    raise SegueError(
                        0,
                        "local_service",
                        f"segue serve exited ({self.process.returncode}): {self.log_tail()}",
                    )
                try:
                    if client.health().get("ok"):
                        return self.url
                except SegueError:
                    pass
                if time.monotonic() > deadline:
                    self.stop()
                    raise SegueError(0, "local_service", f"segue serve did not answer within {timeout:.0f} s")
                time.sleep(0.1)
        finally:
            client.close()

    def log_tail(self, chars: int = 600) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-chars:].strip()
        except OSError:
            return ""

    def stop(self, grace: float = 10.0) -> None:
        """Stop it (SIGTERM, then SIGKILL after ``grace`` seconds)."""
        proc = self.process
        if proc is None:
            return
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.process = None


_STARTED: list[LocalService] = []


def stop_all() -> None:
    """Stop every local service this Blender started (at exit, and when the add-on unregisters)."""
    while _STARTED:
        _STARTED.pop().stop()


atexit.register(stop_all)
