"""Errors as JSON: every error body is a :class:`schemas.ErrorResponse`.

Routes raise :class:`ApiError` (or let a domain error through); :func:`install_error_handlers` maps
each to a status and a stable code, so a client mistake is always a 4xx with a message, never a 500:

=========================================  ======  =====================
exception                                  status  code
=========================================  ======  =====================
``workers.store.NotFoundError``            404     ``not_found``
``motion.GltfError`` (a glTF input)        400     ``invalid_gltf``
``motion.BvhError`` / ``motion.MotionError``  400  ``invalid_bvh``
``RequestValidationError`` / ``ValidationError``  422  ``invalid_request``
``schemas.jobs.RequestError``              422     ``invalid_request``
``engines.registry.UnavailableError``      422     ``unavailable``
``workers.backend.BackendUnavailable``     503     ``backend_unavailable`` (+ ``Retry-After``)
``workers.storage_errors.StoreTimeout``     503     ``store_unavailable`` (+ ``Retry-After``): a stalled store
``starlette.requests.ClientDisconnect``     499     (none: the client left; one log line, no traceback)
``OSError``: a full disk or quota            507     ``storage_full`` (``ENOSPC``, ``EDQUOT``, ``EFBIG``)
``OSError``: a read-only store              507     ``storage_read_only`` (``EROFS``)
``OSError``: an unreachable store           507     ``storage_unavailable`` (``EIO``, ``ESTALE``,
                                                    ``workers.storage_errors.StoreUnavailable``...)
:class:`ApiError`                          its own (413 ``too_large``, 409 ``database_not_ready``...)
``HTTPException`` (routing: 404)           its own ``http_<status>``
``HTTPException`` (routing: 405)           405     ``method_not_allowed`` (+ ``Allow``: every method)
anything else (any other ``OSError`` too) 500     ``internal`` (a bug; logged)
=========================================  ======  =====================
"""

from __future__ import annotations

import logging
from typing import Any, cast

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import ClientDisconnect
from starlette.routing import Match

from engines.registry import UnavailableError
from motion import GltfError, MotionError
from schemas import ErrorBody, ErrorResponse
from schemas.jobs import RequestError
from workers.backend import BackendUnavailable
from workers.storage_errors import StoreTimeout, storage_problem
from workers.store import NotFoundError

log = logging.getLogger("segue.service")


class ApiError(Exception):
    """An error response: HTTP status, stable code, message for a person and optional details."""

    def __init__(
        self,
        status: int,
        code: str,
        message: str,
        details: Any = None,
        headers: dict[str, str] | None = None,
    ) -> None:
        super().__init__(message)
        self.status = status
        self.code = code
        self.message = message
        self.details = details
        self.headers = headers


def conflict(code: str, message: str, details: Any = None) -> ApiError:
    """409: the resource is not in a state that allows the request (e.g. a database still building)."""
    return ApiError(409, code, message, details)


def too_large(limit: int) -> ApiError:
    """413: an upload over ``SEGUE_MAX_UPLOAD_BYTES``."""
    return ApiError(413, "too_large", f"the upload is larger than the {limit}-byte limit", {"limit": limit})


def unauthorized(message: str, invalid: bool = False) -> ApiError:
    """401 with a ``WWW-Authenticate: Bearer`` challenge."""
    challenge = 'Bearer error="invalid_token"' if invalid else "Bearer"
    code = "invalid_token" if invalid else "unauthorized"
    return ApiError(401, code, message, headers={"WWW-Authenticate": challenge})


def error_body(code: str, message: str, details: Any = None) -> dict[str, Any]:
    """The JSON of an :class:`~schemas.ErrorResponse`."""
    return ErrorResponse(error=ErrorBody(code=code, message=message, details=details)).model_dump(
        mode="json", exclude_none=True
    )


def error_response(
    status: int, code: str, message: str, details: Any = None, headers: dict[str, str] | None = None
) -> JSONResponse:
    """A JSON error response."""
    return JSONResponse(error_body(code, message, details), status_code=status, headers=headers)


def validation_details(errors: list[Any]) -> list[dict[str, Any]]:
    """Pydantic errors reduced to JSON-safe ``{"loc", "msg", "type"}`` entries."""
    return [
        {
            "loc": [str(p) for p in e.get("loc", ())],
            "msg": str(e.get("msg", "")),
            "type": str(e.get("type", "")),
        }
        for e in errors
    ]


def validation_message(details: list[dict[str, Any]], limit: int = 3) -> str:
    """One line for a person: the first few errors as ``where: what``."""
    parts = [f"{'.'.join(d['loc']) or 'body'}: {d['msg']}" for d in details[:limit]]
    more = f" (+{len(details) - limit} more)" if len(details) > limit else ""
    return "invalid request: " + "; ".join(parts) + more


async def _api_error(request: Request, exc: Exception) -> JSONResponse:
    exc = cast(ApiError, exc)
    return error_response(exc.status, exc.code, exc.message, exc.details, exc.headers)


async def _not_found(request: Request, exc: Exception) -> JSONResponse:
    return error_response(404, "not_found", str(exc))


async def _motion_error(request: Request, exc: Exception) -> JSONResponse:
    code = "invalid_gltf" if isinstance(exc, GltfError) else "invalid_bvh"
    return error_response(400, code, str(exc))


async def _validation_error(request: Request, exc: Exception) -> JSONResponse:
    details = validation_details(list(cast(RequestValidationError | ValidationError, exc).errors()))
    return error_response(422, "invalid_request", validation_message(details), details)


async def _request_error(request: Request, exc: Exception) -> JSONResponse:
    return error_response(422, "invalid_request", str(exc))


async def _unavailable(request: Request, exc: Exception) -> JSONResponse:
    return error_response(422, "unavailable", str(exc))


HTTP_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE")
"""The methods a 405's ``Allow`` header may name (``OPTIONS`` only with CORS, which answers itself)."""


def allowed_methods(request: Request) -> list[str]:
    """Every method some route answers on this request's path: each method is tried against every
    route (Starlette's own 405 names only the methods of the first route whose path matches, e.g.
    ``GET`` for ``/v1/jobs/{id}``, which ``DELETE`` serves too)."""
    routes = request.app.router.routes
    return [
        method
        for method in HTTP_METHODS
        if any(route.matches({**request.scope, "method": method})[0] == Match.FULL for route in routes)
    ]


async def _http_error(request: Request, exc: Exception) -> JSONResponse:
    exc = cast(StarletteHTTPException, exc)
    headers = dict(exc.headers) if exc.headers else None
    if exc.status_code == 405:
        allowed = allowed_methods(request) or sorted((headers or {}).get("Allow", "").split(", "))
        headers = {**(headers or {}), "Allow": ", ".join(allowed)}
        return error_response(
            405,
            "method_not_allowed",
            f"{request.method} is not allowed on {request.url.path}; allowed: {', '.join(allowed)}",
            {"allowed": allowed},
            headers=headers,
        )
    return error_response(exc.status_code, f"http_{exc.status_code}", str(exc.detail), headers=headers)


async def _backend_unavailable(request: Request, exc: Exception) -> JSONResponse:
    return error_response(
        503,
        "backend_unavailable",
        f"the job backend cannot take this now ({exc}); try again",
        headers={"Retry-After": "5"},
    )


STORE_RETRY_AFTER_S = 10
"""``Retry-After`` of a 503 ``store_unavailable``."""


def _stalled(exc: BaseException) -> StoreTimeout | None:
    """The :class:`StoreTimeout` ``exc`` is or was raised from, if any."""
    current: BaseException | None = exc
    for _ in range(8):
        if current is None:
            return None
        if isinstance(current, StoreTimeout):
            return current
        current = current.__cause__ or current.__context__
    return None


def disconnected(exc: BaseException) -> bool:
    """Whether ``exc`` is, or groups only, :class:`ClientDisconnect` (the client left)."""
    if isinstance(exc, ClientDisconnect):
        return True
    if isinstance(exc, BaseExceptionGroup):
        return all(disconnected(e) for e in exc.exceptions)
    return False


def quiet_response(request: Request, exc: BaseException) -> Response | None:
    """The answer to an exception that is no bug, wherever it surfaces (an exception group, an
    error raised from it): 503 ``store_unavailable`` for a stalled store, 499 for a client that
    left; None for anything else."""
    if disconnected(exc):
        log.warning("%s %s: the client disconnected (499)", request.method, request.url.path)
        return Response(status_code=CLIENT_CLOSED)
    stalled = _stalled(exc)
    if stalled is None and isinstance(exc, BaseExceptionGroup):
        stalled = next((s for s in map(_stalled, exc.exceptions) if s is not None), None)
    return _store_unavailable(request, stalled) if stalled is not None else None


def _store_unavailable(request: Request, exc: StoreTimeout) -> JSONResponse:
    log.warning("%s %s: %s", request.method, request.url.path, exc.strerror)
    return error_response(
        503,
        "store_unavailable",
        f"the store does not answer ({exc.strerror}); try again later",
        headers={"Retry-After": str(STORE_RETRY_AFTER_S)},
    )


async def _client_disconnect(request: Request, exc: Exception) -> Response:
    """The client closed the connection before its request was read: one log line, and 499 (the
    status nobody receives; counted as such in ``/metrics``, not as a 500)."""
    log.warning(
        "%s %s: the client disconnected before its request was read (499)", request.method, request.url.path
    )
    return Response(status_code=CLIENT_CLOSED)


CLIENT_CLOSED = 499
"""The status recorded for a request its client abandoned (nginx's "client closed request")."""


async def _storage(request: Request, exc: Exception) -> Response:
    """503 for a stalled store, 507 for a storage failure
    (:func:`workers.storage_errors.storage_problem`), else 500."""
    stalled = _stalled(exc)
    if stalled is not None:
        return _store_unavailable(request, stalled)
    problem = storage_problem(exc)
    if problem is None:
        return await _internal(request, exc)
    code, message = problem
    log.error("%s %s: %s (%s)", request.method, request.url.path, message, exc)
    return error_response(507, code, message, headers={"Retry-After": "60"})


async def _internal(request: Request, exc: Exception) -> Response:
    stalled = _stalled(exc)  # raised from within another error (e.g. an ExceptionGroup)
    if stalled is not None:
        return _store_unavailable(request, stalled)
    problem = storage_problem(exc)
    if problem is not None:
        log.error("%s %s: %s (%s)", request.method, request.url.path, problem[1], exc)
        return error_response(507, *problem, headers={"Retry-After": "60"})
    log.exception("unhandled error on %s %s", request.method, request.url.path, exc_info=exc)
    return error_response(500, "internal", f"internal error ({type(exc).__name__}); see the server log")


def install_error_handlers(app: FastAPI) -> None:
    """Register the handlers of the table in the module docstring."""
    app.add_exception_handler(ApiError, _api_error)
    app.add_exception_handler(NotFoundError, _not_found)
    app.add_exception_handler(MotionError, _motion_error)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(ValidationError, _validation_error)
    app.add_exception_handler(RequestError, _request_error)
    app.add_exception_handler(UnavailableError, _unavailable)
    app.add_exception_handler(BackendUnavailable, _backend_unavailable)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    app.add_exception_handler(ClientDisconnect, _client_disconnect)
    app.add_exception_handler(OSError, _storage)
    app.add_exception_handler(Exception, _internal)


ERROR_RESPONSES: dict[int | str, dict[str, Any]] = {
    status: {"model": ErrorResponse, "description": text}
    for status, text in {
        400: "invalid BVH content (the message names the file and line)",
        401: "a bearer token is required (auth enabled) or the token is not valid",
        404: "no such clip, database, job or result",
        409: "the resource is not ready (database building, job without a result...)",
        403: "the request comes from a foreign origin (browsers: same origin or SEGUE_CORS_ORIGINS)",
        413: "the body is over its size limit, or the job over the server's work budget",
        415: "a JSON route was sent a body that is not 'Content-Type: application/json'",
        422: "the request is invalid (details lists each problem)",
        429: "too many unfinished jobs or live sessions for this principal (see Retry-After)",
        503: "the server cannot take this now: the job backend or the store does not answer, or "
        "too many uploads are in flight (see Retry-After); nothing was stored",
        507: "the server's storage is full, read-only or unreachable; nothing was stored",
    }.items()
}
"""OpenAPI error responses (all :class:`~schemas.ErrorResponse`), picked per route."""


def responses(
    *statuses: int, extra: dict[int, dict[str, Any]] | None = None
) -> dict[int | str, dict[str, Any]]:
    """The OpenAPI ``responses`` entry for the given error statuses (plus ``extra`` entries); every
    route may answer 507 (its storage failed)."""
    out: dict[int | str, dict[str, Any]] = {k: v for k, v in (extra or {}).items()}
    out.update({s: ERROR_RESPONSES[s] for s in (*statuses, 507)})
    return out
