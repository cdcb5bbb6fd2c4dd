"""Small jobs: the engine-sized work an API request needs, run where engines run.

The API submits them as jobs of kind ``task`` through its backend (so the embedded pool and
``segue worker`` processes both run them) and waits for the terminal event
(:mod:`service.tasks`). The payload is ``{"request": {"task": ..., "budget_s": ...}}``: the
backends' time limits read ``budget_s`` as for a synthesis. A task publishes ``done`` with what it
made, or ``failed`` with ``{"error": {"code", "message", "status"}}`` (``status``: the HTTP status
the API answers with).

* ``clip``: parse a staged upload in full and store it as a clip (:meth:`Store.put_clip`);
  ``done`` carries the :class:`~schemas.ClipInfo`.
* ``export``: make a result's download (:func:`workers.result_export.make_export`) and keep it in
  the store under its key; ``done`` carries ``{"export": key, "bytes": n}``.
"""

from __future__ import annotations

from typing import Any

from motion import BvhLimits, GltfError, MotionError
from schemas import EventType

from .result_export import ExportFailure, ExportSpec, make_export
from .store import NotFoundError, Store

TASK_BUDGET_S = 120.0
"""``budget_s`` of a small job: the embedded pool stops it after this + ``job_grace_s``, a Redis
worker's entry stays fresh for twice this + ``hang_grace_s``."""


class TaskFailure(Exception):
    """A task that cannot complete: HTTP ``status``, error ``code`` and message."""

    def __init__(self, status: int, code: str, message: str) -> None:
        super().__init__(message)
        self.status, self.code, self.message = status, code, message


def task_payload(task: str, **fields: Any) -> dict[str, Any]:
    """The job payload of a small job (``fields`` JSON-safe)."""
    return {"request": {"task": task, "budget_s": TASK_BUDGET_S, **fields}}


def error_code(exc: MotionError) -> str:
    """The API's code for an input file that cannot be read: ``invalid_gltf`` for a glTF file,
    ``invalid_bvh`` for the rest (BVH files, and motion errors not tied to a file type)."""
    return "invalid_gltf" if isinstance(exc, GltfError) else "invalid_bvh"


def _clip(store: Store, request: dict[str, Any]) -> dict[str, Any]:
    key = str(request["staged"])
    try:
        data = store.staged_bytes(key)
    except NotFoundError:
        if request.get("digest"):  # stored meanwhile by a concurrent upload of the same bytes
            return {"clip": store.clip_info(str(request["digest"])).model_dump(mode="json")}
        raise
    limits = BvhLimits(*(int(v) for v in request["limits"]))
    try:
        info = store.put_clip(str(request["name"]), data, limits, request.get("units"))
    except MotionError as exc:
        raise TaskFailure(400, error_code(exc), str(exc)) from None
    finally:
        store.delete_staged(key)
    return {"clip": info.model_dump(mode="json")}


def _export(store: Store, request: dict[str, Any]) -> dict[str, Any]:
    spec = ExportSpec.from_dict(request["spec"])
    try:
        data = make_export(store, spec)
    except ExportFailure as exc:
        raise TaskFailure(exc.status, exc.code, exc.message) from None
    key = spec.key()
    store.put_export(spec.job, key, data)
    return {"export": key, "bytes": len(data)}


TASKS = {"clip": _clip, "export": _export}


def run_task(store: Store, request: dict[str, Any], publish: Any) -> None:
    """Run the small job ``request`` and publish its terminal event (``done`` or ``failed``)."""
    name = str(request.get("task"))
    handler = TASKS.get(name)
    try:
        if handler is None:
            raise TaskFailure(500, "invalid_job", f"unknown task {name!r}")
        data = handler(store, request)
    except TaskFailure as exc:
        error = {"code": exc.code, "message": exc.message, "status": exc.status}
        publish(EventType.failed, {"error": error})
        return
    except NotFoundError as exc:
        publish(EventType.failed, {"error": {"code": "not_found", "message": str(exc), "status": 404}})
        return
    except MotionError as exc:  # a character file that is not one (as the API answers MotionError)
        publish(EventType.failed, {"error": {"code": error_code(exc), "message": str(exc), "status": 400}})
        return
    publish(EventType.done, {"result": None, **data})
