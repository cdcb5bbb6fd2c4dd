"""Rhythmic synthesis engine (Kim, Park & Shin 2003): database spec and request."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .bases import DatabaseSpecBase, JobRequestBase


class RhythmDatabaseSpec(DatabaseSpecBase):
    """Rhythmic-motion database: example dances cut into basic movements at motion beats."""

    kind: Literal["rhythm"] = "rhythm"
    beats_per_movement: int = Field(default=4, ge=1, le=16)


class RhythmRequest(JobRequestBase):
    """A dance synchronized to music."""

    engine: Literal["rhythm"] = "rhythm"
