"""JSON request bodies: one reader for every JSON route.

Every JSON route reads its body through :func:`read_json`, which

* refuses a body that does not declare ``Content-Type: application/json`` (or ``application/*+json``)
  with 415: a web page can send ``text/plain``, form and multipart bodies to any server without a
  CORS preflight, but not JSON, so this is the first CSRF defence (``service.guard`` checks Host and
  Origin as well);
* refuses more than ``SEGUE_MAX_JSON_BYTES`` (default 1 MiB) with 413, while reading;
* parses off the event loop (a worker thread), at most ``SEGUE_MAX_PARSES`` bodies at once, with
  ``pydantic_core.from_json`` (the Rust ``jiter`` parser pydantic uses): ``NaN``/``Infinity`` literals
  are refused and nesting deeper than its recursion limit (200) is an error, never a
  ``RecursionError``; numbers that overflow a double (``1e999``) are refused too.

Every refusal is a 4xx :class:`~service.errors.ApiError` naming the problem.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import anyio
import pydantic_core
from fastapi import Depends
from starlette.requests import Request

from .deps import SettingsDep, parse_limiter
from .errors import ApiError, responses
from .settings import Settings
from .uploads import read_body

Model = TypeVar("Model")


def is_json_type(content_type: str) -> bool:
    """True for ``application/json`` and ``application/<anything>+json`` (parameters ignored)."""
    media = content_type.split(";", 1)[0].strip().lower()
    return media == "application/json" or (media.startswith("application/") and media.endswith("+json"))


def _non_finite(value: Any) -> bool:
    """True when a parsed JSON value holds an infinite float anywhere (iterative: no recursion)."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, float):
            if not math.isfinite(item):
                return True
        elif isinstance(item, dict):
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
    return False


def parse_json_bytes(data: bytes) -> Any:
    """Parse JSON text strictly (see the module docstring); raises :class:`ApiError` (422)."""
    if not data.strip():
        raise ApiError(422, "invalid_request", "the request body is empty; send a JSON document")
    try:
        value = pydantic_core.from_json(data, allow_inf_nan=False, cache_strings=False)
    except ValueError as exc:
        message = str(exc)
        if "recursion limit" in message:
            raise ApiError(
                422, "invalid_request", f"the JSON document is nested too deeply ({message})"
            ) from None
        raise ApiError(
            422,
            "invalid_request",
            f"the request is not valid JSON ({message}; NaN and Infinity are not JSON)",
        ) from None
    if b"\\u0000" in data.lower():
        raise ApiError(
            422, "invalid_request", "the request holds a NUL character (\\u0000), which no name may hold"
        )
    if _non_finite(value):
        raise ApiError(
            422, "invalid_request", "the request holds a number too large for a double (e.g. 1e999)"
        )
    return value


async def read_json(request: Request, settings: Settings) -> Any:
    """The request's JSON body, parsed off the event loop (see the module docstring)."""
    content_type = request.headers.get("content-type", "")
    if not is_json_type(content_type):
        raise ApiError(
            415,
            "unsupported_media_type",
            f"this route takes a JSON body sent as 'Content-Type: application/json', not {content_type!r}",
            {"content_type": content_type},
        )
    data = await read_body(request, settings.max_json_bytes)
    return await anyio.to_thread.run_sync(parse_json_bytes, data, limiter=parse_limiter(request, settings))


def json_body(validate: Callable[[Any], Model]) -> Callable[[Request, Settings], Awaitable[Model]]:
    """A dependency giving a route its JSON body as a model: read with :func:`read_json`, then
    ``validate(value)`` (a pydantic validator: errors are 422 ``invalid_request``) in a worker
    thread, since validating a large body takes time. Use it as
    ``spec: Annotated[Spec, Depends(json_body(parse_spec))]``, after the caller's principal."""

    async def body(request: Request, settings: SettingsDep) -> Model:
        value = await read_json(request, settings)
        return await anyio.to_thread.run_sync(validate, value, limiter=parse_limiter(request, settings))

    return body


def json_body_doc(schema_ref: str, description: str) -> dict[str, Any]:
    """OpenAPI ``requestBody`` for a route that reads its body with :func:`read_json`."""
    return {
        "requestBody": {
            "required": True,
            "description": description,
            "content": {"application/json": {"schema": {"$ref": f"#/components/schemas/{schema_ref}"}}},
        }
    }


def carries_body(request: Request) -> bool:
    """True when the request declares a body (a non-zero ``Content-Length`` or any
    ``Transfer-Encoding``)."""
    length = request.headers.get("content-length", "").strip()
    return bool(request.headers.get("transfer-encoding")) or (length not in ("", "0"))


async def refuse_foreign_body(request: Request) -> None:
    """Bodyless writes (``DELETE``, ``POST .../cancel``): a plain ``curl -X DELETE`` is fine, but a
    body, if one is sent, must be ``Content-Type: application/json`` (415 otherwise), as on every
    JSON route. Forgery is covered elsewhere: a web page cannot send a cross-origin ``DELETE``
    without a CORS preflight, which only ``SEGUE_CORS_ORIGINS`` pass, and every ``POST`` from a
    browser carries an ``Origin`` that :class:`~service.guard.HostOriginGuard` checks."""
    if not carries_body(request):
        return
    content_type = request.headers.get("content-type", "")
    if not is_json_type(content_type):
        raise ApiError(
            415,
            "unsupported_media_type",
            f"this {request.method} takes no body, or a JSON one sent as 'Content-Type: application/json', "
            f"not {content_type or 'no content type'!r}",
            {"content_type": content_type},
        )


BodylessWrite = Depends(refuse_foreign_body)
"""Add to a bodyless write route: ``dependencies=[BodylessWrite]``."""


def delete_route(*statuses: int) -> dict[str, Any]:
    """The options of a ``DELETE`` route: 204, the foreign-body guard, and its error responses
    (401, 404, 415, 422 and ``statuses``): ``@router.delete("/{id}", **delete_route())``."""
    return {
        "status_code": 204,
        "dependencies": [BodylessWrite],
        "responses": responses(*sorted({401, 404, 415, 422, *statuses})),
    }
