"""Shared pieces of the contract: the schema version and the error body."""

from __future__ import annotations

from enum import StrEnum
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


class FeetMode(StrEnum):
    """What the clean-up does to the feet (``feet`` of a request, ``--feet``, ``feet=`` of a
    download): ``lock`` planted feet held in place and kept on the floor; ``grounding`` feet kept
    on the floor only (planted ones rest on it, none goes under it) along their own path; ``free``
    the motion as synthesized (or transferred)."""

    lock = "lock"
    grounding = "grounding"
    free = "free"


FEET_DESCRIPTION = (
    "lock | grounding | free: planted feet held in place and on the floor, on the floor only, or "
    "left as synthesized (default: lock with footskate, free without; given, it wins over footskate)"
)


def feet_mode_of(footskate: bool, feet: FeetMode | None) -> FeetMode:
    """The clean-up a request asks for: ``feet`` when given, else ``footskate``'s (lock or free)."""
    if feet is not None:
        return feet
    return FeetMode.lock if footskate else FeetMode.free
