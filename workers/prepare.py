"""One preparation step for a synthesis request, wherever it comes from: the API at submission,
the worker before it runs the job, the CLI before it runs a request file.

:func:`prepare` parses the request (with its engine's model), finds its database, checks that it
is ready and of the kind its engine needs, resolves the request's input files once (to upload
ids, recorded in ``request.inputs``) and attaches their bytes; :func:`prepare_in_dir` does the
same against a database directory and files beside the request file. Each refusal is a
:class:`PrepareError` with the API's error code and HTTP status, which the API answers with, the
worker puts in its ``failed`` event and the CLI prints.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from engines.registry import EngineClass, engine_class, parse_job_request
from schemas import DatabaseInfo, DatabaseStatus
from schemas.bases import JobRequestBase

from .inputs import InputError, attach_from_dir, attach_resolved, resolve_inputs
from .store import Store, Visible


class PrepareError(Exception):
    """A request that cannot run as it stands: ``code`` (the API's error code), ``status`` (its
    HTTP status), the message and the error's ``details``."""

    def __init__(self, code: str, message: str, status: int = 422, details: dict[str, Any] | None = None):
        super().__init__(message)
        self.code, self.message, self.status = code, message, status
        self.details = details or {}


@dataclass(slots=True)
class Prepared:
    """A request ready to run: parsed, its inputs attached, its engine and its database known."""

    request: JobRequestBase
    engine: EngineClass
    database: DatabaseInfo


def parse(request: JobRequestBase | Mapping[str, Any] | str | bytes) -> JobRequestBase:
    """The request validated with its engine's model (a parsed request is returned as it is)."""
    return request if isinstance(request, JobRequestBase) else parse_job_request(request)


def check_database(request: JobRequestBase, info: DatabaseInfo) -> EngineClass:
    """The request's engine class, once ``info`` is ready and of the kind it needs; raises
    :class:`PrepareError` (``database_not_ready`` 409, ``wrong_database_kind`` 422) and
    :class:`engines.registry.UnavailableError`."""
    if info.status != DatabaseStatus.ready:
        detail = f" ({info.error})" if info.error else ""
        raise PrepareError(
            "database_not_ready",
            f"database {info.id} is {info.status.value}{detail}; submit once it is ready",
            409,
            {"database": info.id, "status": info.status.value, "build_job": info.build_job},
        )
    engine = engine_class(request.engine)
    if engine.kind != info.kind:
        raise PrepareError(
            "wrong_database_kind",
            f"engine {request.engine!r} needs a {engine.kind!r} database; "
            f"database {info.id} is {info.kind!r}",
        )
    return engine


def prepare(
    request: JobRequestBase | Mapping[str, Any] | str | bytes,
    store: Store,
    *,
    visible: Visible | None = None,
    database: Callable[[str], DatabaseInfo] | None = None,
    holder: str | None = None,
) -> Prepared:
    """Parse, find the database (``database``: how to look an id up, default the store's; the API
    checks ownership there), check it and resolve and attach the inputs among the uploads
    ``visible`` accepts, by ``holder``'s own upload names when given (module doc). Raises
    :class:`PrepareError`, the lookup's ``NotFoundError``, pydantic's ``ValidationError`` and
    ``UnavailableError``."""
    parsed = parse(request)
    if parsed.database is None:
        raise PrepareError("invalid_request", "the request names no database ('database': <database id>)")
    info = (database or store.database_info)(parsed.database)
    engine = check_database(parsed, info)
    try:
        parsed.inputs = resolve_inputs(store, parsed, visible, holder)
        attach_resolved(store, parsed)
    except InputError as exc:
        raise PrepareError(exc.code, str(exc), 422, {"inputs": parsed.input_files()}) from None
    return Prepared(parsed, engine, info)


def prepare_in_dir(
    request: JobRequestBase | Mapping[str, Any] | str | bytes, request_dir: Path, db_dir: Path
) -> Prepared:
    """:func:`prepare` for the CLI: the database is the directory ``db_dir`` (its ``info.json``),
    input files are read from paths relative to ``request_dir``."""
    parsed = parse(request)
    try:
        info = DatabaseInfo.model_validate_json((db_dir / "info.json").read_bytes())
    except OSError as exc:
        raise PrepareError(
            "invalid_request", f"{db_dir} is not a database directory ({exc.strerror or exc})"
        ) from None
    engine = check_database(parsed, info)
    try:
        attach_from_dir(parsed, request_dir)
    except InputError as exc:
        raise PrepareError(exc.code, str(exc), 422, {"inputs": parsed.input_files()}) from None
    return Prepared(parsed, engine, info)
