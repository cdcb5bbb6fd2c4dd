"""Engines run in a child process that a thread of the worker watches: liveness a busy engine cannot
starve, and budgets, cancels and memory enforced from outside the engine.

An :class:`EngineProcess` is one long-lived child process (``spawn``) that runs one job at a time
with :func:`workers.execute.execute_job` and sends its events back over a pipe; it keeps its
:class:`~workers.engine_cache.EngineCache` between jobs. The owner (the embedded backend in the API
process, or a ``segue worker``) gives it a :class:`Task`; a watch thread of the owner relays the
child's events (``on_event``) and calls ``on_end`` once per task with an :data:`Outcome`:

* ``finished`` — the child reported the job over (it published the terminal event itself);
* ``released`` — the child could not run the job on this host (its cache disk is full:
  :class:`~workers.dbcache.CacheFull`) and published no terminal event: the owner gives the job
  to another worker, or fails it naming the host's problem;
* ``crashed`` — the child died (SIGKILL, the OOM killer, a segfault): the owner re-runs the job;
* ``cancel_timeout`` — a cancel was asked and the job had not ended ``cancel_grace_s`` later;
* ``time_limit`` — the job ran past its hard time limit (``budget_s`` + room for assembly), or
  loading its database took longer than ``load_timeout_s`` (the load is not charged to the job's
  limit: the child says when it starts and ends loading, and the job's clock stops meanwhile);
* ``memory_limit`` — the child's resident memory passed ``max_rss_bytes``.

In the last three cases the supervisor kills the child (SIGKILL); the owner publishes the terminal
event (:func:`terminal_after_kill`). Every dead child is replaced at once. Because the owner's threads
do no engine work, the owner's heartbeats (Redis pending-entry refreshes) keep their pace however
busy the engine is. A child dies with its owner (:func:`die_with_parent`: Linux's parent-death
signal, checked against the parent it was started by, and a poll as a second guard), so no engine
process outlives the worker that relays its events; every durable write it makes is checked
against its owner and its job's attempt first (:class:`workers.fencing.FencedStore`). Children are
started from a thread that lives as long as they do (the watch thread, or the embedded backend's
event loop thread): the kernel's signal follows the thread that started them.

Hand-written because ``concurrent.futures.ProcessPoolExecutor`` breaks for good when one process
dies (``BrokenProcessPool``) and cannot kill the process running a given job.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from typing import Any, Literal

from schemas import EventType

log = logging.getLogger("segue.supervisor")

Outcome = Literal["finished", "released", "crashed", "cancel_timeout", "time_limit", "memory_limit"]

PAGE_SIZE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


@dataclass(slots=True)
class ChildConfig:
    """What a child process needs to run jobs (picklable)."""

    store_root: str
    """The store's location: a directory or a store URL (``s3://bucket/prefix``)."""
    plugins: list[str] = field(default_factory=list)
    engine_cache_bytes: int = 2048 << 20
    cache_url: str | None = None
    prefix: str = "segue:"
    chunk_size: int = 4 << 20
    cache_dir: str | None = None
    """The local cache directory (databases downloaded from an object store); default: the
    store's directory when local, else ``./segue-data``."""
    disk_cache_bytes: int = 8 << 30
    cache_max_object_bytes: int = 64 << 20
    fence_url: str | None = None
    """The queue Redis holding the jobs' fencing tokens (:mod:`workers.fencing`): each task's writes
    are checked against its attempt and its ``should_stop`` polls it; None (embedded): no fence."""


@dataclass(slots=True)
class Task:
    """One run of a job in a child process."""

    job_id: str
    kind: str
    payload: dict[str, Any]
    attempt: int = 1
    time_limit_s: float | None = None
    owner: str | None = None
    """The principal that submitted the job (its place in the fair queue)."""
    seq: int = 0
    started: float = 0.0
    cancel_asked: float | None = None
    loading_since: float | None = None
    """When the child started loading the job's database (timed apart from the job's limit)."""
    best: str | None = None
    released: str | None = None
    """Why the child gave the job back without ending it (``released``), else None."""
    terminal: bool = False
    stale: bool = False
    """The run lost its job to a later attempt (its events are refused; it is being stopped)."""
    context: Any = None


def request_budget_s(payload: dict[str, Any]) -> float:
    """A synthesis job's ``budget_s`` (10 s, the request default, when it cannot be read)."""
    request = payload.get("request")
    budget = request.get("budget_s", 10.0) if isinstance(request, dict) else 10.0
    return float(budget) if isinstance(budget, int | float) else 10.0


def time_limit(kind: str, payload: dict[str, Any], grace_s: float, build_timeout_s: float) -> float:
    """Hard time limit of a job, seconds: builds ``build_timeout_s``; syntheses their ``budget_s``
    plus ``grace_s`` (database loading and the assembly after the search; the work budget checked at
    submission keeps that bounded)."""
    if kind == "build":
        return build_timeout_s
    return request_budget_s(payload) + grace_s


def terminal_after_kill(outcome: Outcome, task: Task, detail: str) -> tuple[EventType, dict[str, Any]]:
    """The terminal event the owner publishes after the supervisor stopped a job."""
    if outcome == "cancel_timeout":
        return EventType.cancelled, {"result": task.best, "stopped": "killed after the cancel grace"}
    if outcome == "time_limit" and task.best is not None:
        return EventType.done, {"result": task.best, "stopped": "time_limit", "message": detail}
    code = "time_limit" if outcome == "time_limit" else "memory_limit"
    return EventType.failed, {"error": {"code": code, "message": detail}, "result": task.best}


def rss_bytes(pid: int) -> int:
    """Resident memory of a process (Linux ``/proc``; 0 when unknown)."""
    try:
        with open(f"/proc/{pid}/statm", "rb") as fh:
            return int(fh.read().split()[1]) * PAGE_SIZE
    except (OSError, IndexError, ValueError):
        return 0


# -- the child --------------------------------------------------------------------------------------
PR_SET_PDEATHSIG = 1
"""``prctl`` option: the signal the kernel sends a process when the thread that created it exits."""
PARENT_DEATH_SIGNAL = signal.SIGUSR1


def parent_gone(parent: int) -> bool:
    """True once the process that started this one is no longer its parent (it died: the child was
    re-parented to init or a subreaper)."""
    return os.getppid() != parent


def _exit_if_orphaned(parent: int) -> None:
    """Kill this process (SIGKILL: no handler, no ``atexit``, no flush) when its owner is gone."""
    if parent_gone(parent):
        os.kill(os.getpid(), signal.SIGKILL)


def die_with_parent(parent: int) -> bool:
    """Make this (child) process die with the owner process ``parent`` that started it; True when the
    kernel will tell it (Linux), False where only :func:`_watch_parent`'s poll does.

    Linux sends :data:`PARENT_DEATH_SIGNAL` when the *thread* that created this process exits
    (``prctl(PR_SET_PDEATHSIG)``), which is also its owner's death (SIGKILL, the OOM killer). Its
    handler checks that the parent really changed before killing this process (a spawning thread
    that ended while its process lives is not the owner's death: the signal is then ignored), and
    the same check runs once right after ``prctl``, since an owner that died before the call sends
    nothing. So an engine process never outlives its worker: it cannot run the catch-all of a job
    whose events nobody reads and write a record the runtime did not decide (an orphan's
    ``failed``). The Python handler runs before the next bytecode, so no Python code of the job
    runs after the signal arrives."""
    armed = False
    if sys.platform.startswith("linux"):
        signal.signal(PARENT_DEATH_SIGNAL, lambda _sig, _frame: _exit_if_orphaned(parent))
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            armed = libc.prctl(PR_SET_PDEATHSIG, int(PARENT_DEATH_SIGNAL), 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
        if not armed:
            log.warning("prctl(PR_SET_PDEATHSIG) failed; the engine process polls its parent instead")
    _exit_if_orphaned(parent)  # the owner died before the signal was armed
    return armed


def _watch_parent(parent: int) -> None:
    """The portable fallback of :func:`die_with_parent` (and a second guard): poll the parent."""
    while True:
        time.sleep(0.5)
        _exit_if_orphaned(parent)  # the worker is gone: nobody will read our events


def _fence_client(config: ChildConfig) -> tuple[Any, Any] | None:
    """The child's client of the queue Redis and its key names (None without ``fence_url``)."""
    if not config.fence_url:
        return None
    import redis

    from .redis_keys import RedisKeys

    client = redis.Redis.from_url(config.fence_url, socket_timeout=2, socket_connect_timeout=2)
    return client, RedisKeys(config.prefix)


def _child_main(tasks: Connection, events: Connection, cancel: Any, config: ChildConfig, parent: int) -> None:
    import importlib

    from motion.allocator import tune_process

    from .dbcache import CacheFull
    from .engine_cache import EngineCache
    from .execute import execute_job
    from .fencing import Fence, FencedStore

    die_with_parent(parent)
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True, name="segue-parent-watch").start()
    tune_process()
    for module in config.plugins:
        importlib.import_module(module)
    fence_client = _fence_client(config)
    object_cache = None
    if config.cache_url and config.cache_max_object_bytes > 0:
        import redis

        from .redis_cache import DatabaseCache
        from .redis_keys import RedisKeys

        object_cache = DatabaseCache(
            redis.Redis.from_url(config.cache_url),
            RedisKeys(config.prefix),
            chunk_size=config.chunk_size,
            max_object_bytes=config.cache_max_object_bytes,
        )
    store = FencedStore(
        config.store_root,
        config.cache_dir,
        disk_cache_bytes=config.disk_cache_bytes,
        object_cache=object_cache,
    )
    store.parent = parent
    cache = EngineCache(config.engine_cache_bytes)
    events.send(("ready", os.getpid()))
    while True:
        try:
            message = tasks.recv()
        except (EOFError, OSError):
            return
        if message is None:
            return
        seq, job_id, kind, payload, attempt = message
        fence = None
        if fence_client is not None:
            client, keys = fence_client
            fence = Fence(client, keys.attempt(job_id), job_id, attempt)
        store.fence = fence

        def publish(type_: EventType, data: dict[str, Any], seq: int = seq) -> None:
            events.send(("event", seq, type_.value, data, time.time()))

        def should_stop(seq: int = seq, fence: Fence | None = fence) -> bool:
            return bool(cancel.value == seq) or (fence is not None and fence.lost())

        def on_load(loading: bool, seq: int = seq) -> None:
            events.send(("load", seq, loading, time.monotonic()))

        try:
            execute_job(store, job_id, kind, payload, publish, should_stop, cache, attempt, on_load=on_load)
        except CacheFull as exc:
            events.send(("release", seq, str(exc)))
        events.send(("end", seq))


# -- the supervisor -----------------------------------------------------------------------------------
OnEvent = Callable[[Task, EventType, dict[str, Any], float], None]
OnEnd = Callable[[Task, Outcome, str], None]


class EngineProcess:
    """One supervised child process running one job at a time (see the module docstring)."""

    def __init__(
        self,
        name: str,
        config: ChildConfig,
        on_event: OnEvent,
        on_end: OnEnd,
        *,
        cancel_grace_s: float = 2.0,
        max_rss_bytes: int | None = None,
        load_timeout_s: float | None = None,
        poll_s: float = 0.05,
        on_ready: Callable[[], None] | None = None,
        spawner: Callable[[Callable[[], None]], None] | None = None,
    ) -> None:
        self.name, self.config = name, config
        self.on_ready = on_ready
        self.spawner = spawner
        """Runs ``process.start`` (e.g. on the owner's main thread, so the children are children of
        that thread in ``/proc/<pid>/task/<pid>/children``); default: the watch thread."""
        self.on_event, self.on_end = on_event, on_end
        self.cancel_grace_s, self.max_rss_bytes, self.poll_s = cancel_grace_s, max_rss_bytes, poll_s
        self.load_timeout_s = load_timeout_s
        self._ctx = mp.get_context("spawn")
        self._lock = threading.Lock()
        self._task: Task | None = None
        self._seq = 0
        self._closing = False
        self._process: Any = None
        self._tasks: Connection | None = None
        self._events: Connection | None = None
        self._cancel: Any = None
        self._thread: threading.Thread | None = None
        self.ready = threading.Event()
        self.restarts = 0
        self.failed_starts = 0
        self.pid: int | None = None

    # -- owner side ---------------------------------------------------------------------------
    def start(self) -> None:
        """Start the child and the watch thread (returns at once; ``ready`` is set once it runs)."""
        self._thread = threading.Thread(target=self._watch, name=f"segue-supervisor-{self.name}", daemon=True)
        self._thread.start()

    @property
    def busy(self) -> bool:
        return self._task is not None

    @property
    def idle(self) -> bool:
        """Ready for a task (alive, started and not running one)."""
        return self.ready.is_set() and self._task is None and not self._closing

    @property
    def task(self) -> Task | None:
        return self._task

    def run(self, task: Task) -> bool:
        """Hand ``task`` to the child; False when it is busy or not ready (try another)."""
        with self._lock:
            if not self.idle or self._tasks is None:
                return False
            self._seq += 1
            task.seq, task.started = self._seq, time.monotonic()
            self._task = task
            try:
                self._tasks.send((task.seq, task.job_id, task.kind, task.payload, task.attempt))
            except (OSError, ValueError):
                self._task = None
                return False
            return True

    def cancel(self, job_id: str) -> bool:
        """Ask the running job to stop (it has ``cancel_grace_s`` to end by itself); False when this
        process does not run ``job_id``."""
        with self._lock:
            task = self._task
            if task is None or task.job_id != job_id:
                return False
            if task.cancel_asked is None:
                task.cancel_asked = time.monotonic()
                if self._cancel is not None:
                    self._cancel.value = task.seq
            return True

    def close(self, timeout: float = 5.0) -> None:
        """Stop the child (killed if it does not stop) and the watch thread."""
        self._closing = True
        with contextlib.suppress(OSError, ValueError, AttributeError):
            if self._tasks is not None:
                self._tasks.send(None)
        process = self._process
        if process is not None:
            process.join(timeout if self._task is None else 0.5)
            if process.is_alive():
                process.kill()
                process.join(5)
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    # -- watch thread ---------------------------------------------------------------------------
    def _spawn(self) -> bool:
        parent_tasks, child_tasks = self._ctx.Pipe(duplex=False)  # (receive end, send end)
        parent_events, child_events = self._ctx.Pipe(duplex=False)
        cancel = self._ctx.RawValue("q", 0)
        process = self._ctx.Process(
            target=_child_main,
            args=(parent_tasks, child_events, cancel, self.config, os.getpid()),
            name=f"segue-engine-{self.name}",
            daemon=True,
        )
        try:
            if self.spawner is not None:
                self.spawner(process.start)
            else:
                process.start()
        except Exception:
            log.exception("engine process %s could not start", self.name)
            return False
        parent_tasks.close()
        child_events.close()
        self._process, self._tasks, self._events, self._cancel = process, child_tasks, parent_events, cancel
        self.pid = process.pid
        return True

    def _watch(self) -> None:
        backoff = 0.2
        while not self._closing:
            if not self._spawn():
                self.failed_starts += 1
                time.sleep(backoff)
                backoff = min(backoff * 2, 10.0)
                continue
            outcome = self._supervise()
            self.ready.clear()
            if self._closing:
                break
            self.restarts += 1
            if outcome == "start_failed":
                self.failed_starts += 1
                time.sleep(backoff)
                backoff = min(backoff * 2, 10.0)
            else:
                backoff = 0.2
        self._cleanup()

    def _cleanup(self) -> None:
        for conn in (self._tasks, self._events):
            with contextlib.suppress(OSError):
                if conn is not None:
                    conn.close()

    def _supervise(self) -> str:
        """Relay events until the child dies (or is killed); returns why it ended."""
        process, events = self._process, self._events
        assert events is not None
        next_rss = 0.0
        while True:
            try:
                has_message = events.poll(self.poll_s)
            except (OSError, EOFError):
                has_message = False
            if has_message:
                try:
                    message = events.recv()
                except (EOFError, OSError):
                    return self._died(process, "crashed", "the engine process died")
                self._handle(message)
                continue
            if not process.is_alive():
                self._drain(events)
                return self._died(
                    process, "crashed", f"the engine process died (exit code {process.exitcode})"
                )
            if self._closing:
                return "closing"
            task = self._task
            if task is None:
                continue
            now = time.monotonic()
            if task.cancel_asked is not None and now - task.cancel_asked > self.cancel_grace_s:
                return self._kill(
                    process,
                    "cancel_timeout",
                    f"the job did not stop {self.cancel_grace_s:g} s after its cancel",
                )
            if task.loading_since is not None:
                if self.load_timeout_s is not None and now - task.loading_since > self.load_timeout_s:
                    return self._kill(
                        process,
                        "time_limit",
                        f"loading the job's database took longer than {self.load_timeout_s:g} s",
                    )
            elif task.time_limit_s is not None and now - task.started > task.time_limit_s:
                return self._kill(
                    process, "time_limit", f"the job ran past its {task.time_limit_s:g}-s time limit"
                )
            if self.max_rss_bytes and now >= next_rss:
                next_rss = now + 0.25
                rss = rss_bytes(process.pid)
                if rss > self.max_rss_bytes:
                    return self._kill(
                        process,
                        "memory_limit",
                        f"the job used {rss / 2**20:.0f} MiB, over the "
                        f"{self.max_rss_bytes / 2**20:.0f}-MiB limit",
                    )

    def _handle(self, message: tuple[Any, ...]) -> None:
        kind = message[0]
        if kind == "ready":
            self.failed_starts = 0
            self.ready.set()
            if self.on_ready is not None:
                try:
                    self.on_ready()
                except Exception:
                    log.exception("engine process %s: the ready callback failed", self.name)
            return
        task = self._task
        if task is None or message[1] != task.seq:
            return  # a late message of a task already given up
        if kind == "event":
            _, _, type_value, data, when = message
            type_ = EventType(type_value)
            if type_ == EventType.solution and isinstance(data.get("result"), str):
                task.best = data["result"]
            if type_.terminal:
                task.terminal = True
            try:
                self.on_event(task, type_, data, when)
            except Exception:
                log.exception("job %s: relaying a %s event failed", task.job_id, type_.value)
        elif kind == "load":
            now = time.monotonic()
            if message[2]:
                task.loading_since = now
            elif task.loading_since is not None:
                task.started += now - task.loading_since  # the load is not the job's time
                task.loading_since = None
        elif kind == "release":
            task.released = str(message[2])
        elif kind == "end":
            if task.released is not None:
                self._finish(task, "released", task.released)
            else:
                self._finish(task, "finished", "")

    def _finish(self, task: Task, outcome: Outcome, detail: str) -> None:
        with self._lock:
            self._task = None
            if self._cancel is not None:
                self._cancel.value = 0
        try:
            self.on_end(task, outcome, detail)
        except Exception:
            log.exception("job %s: ending it (%s) failed", task.job_id, outcome)

    def _drain(self, events: Connection) -> None:
        """Relay what the child sent before it died."""
        with contextlib.suppress(EOFError, OSError):
            while events.poll(0):
                self._handle(events.recv())

    def _kill(self, process: Any, outcome: Outcome, detail: str) -> str:
        task = self._task
        log.warning(
            "engine process %s (job %s): %s; killing it", self.name, task.job_id if task else None, detail
        )
        process.kill()
        process.join(5)
        return self._died(process, outcome, detail)

    def _died(self, process: Any, outcome: Outcome, detail: str) -> str:
        process.join(1)
        if self._events is not None:
            self._drain(self._events)
        was_ready = self.ready.is_set()
        self.ready.clear()
        task = self._task
        if task is not None:
            self._finish(task, outcome, detail)
        elif not was_ready and not self._closing:
            log.error("engine process %s died while starting (exit code %s)", self.name, process.exitcode)
            return "start_failed"
        if outcome == "crashed":
            log.warning("engine process %s: %s", self.name, detail)
        return outcome


def engine_plugins(configured: str | None = None) -> list[str]:
    """The plugin modules the children import: ``configured`` (``SEGUE_ENGINE_PLUGINS``, comma-separated)
    and the modules of the engines registered in this process that are not built in, so an engine
    registered by the owner runs in its children."""
    from engines.registry import ENGINES

    registered = {cls.__module__ for cls in ENGINES.values() if not cls.__module__.startswith("engines.")}
    named = {name.strip() for name in (configured or "").split(",") if name.strip()}
    return sorted(registered | named)
