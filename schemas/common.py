"""Shared pieces of the contract: the schema version and the error body."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

SCHEMA_VERSION = 1
"""Bumped whenever a change to the specs changes what a database build produces (part of the
content address of databases)."""


class Strict(BaseModel):
    """Base for request models: unknown fields are errors (a typo must not be silently ignored), and
    every number is finite (``NaN`` and ``Infinity`` are refused wherever a float is expected, so no
    request can carry them into an engine or a result)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class ErrorBody(BaseModel):
    code: str = Field(description="stable machine-readable code, e.g. 'invalid_bvh', 'not_found'")
    message: str = Field(description="what went wrong, for a person")
    details: Any | None = Field(default=None, description="structured details (e.g. validation errors)")


class ErrorResponse(BaseModel):
    """Every 4xx/5xx response body."""

    error: ErrorBody
