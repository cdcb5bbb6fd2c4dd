"""Base models every engine's specs and requests extend (kept apart so engine schema modules can
import them without cycles)."""

from __future__ import annotations

from pydantic import Field

from .clips import ClipSource
from .common import Strict


class DatabaseSpecBase(Strict):
    """Settings every database kind shares."""

    kind: str
    clips: list[ClipSource] = Field(min_length=1, max_length=2000)
    fps: float | None = Field(default=None, gt=0, le=1000, description="resample every clip to this rate")
    name: str | None = Field(default=None, max_length=128)


class JobRequestBase(Strict):
    """Settings every synthesis request shares."""

    database: str | None = Field(
        default=None, description="database id (API); the CLI's --db directory supplies it otherwise"
    )
    budget_s: float = Field(default=10.0, gt=0, le=3600, description="anytime search budget, seconds")
    seed: int = Field(default=0, ge=0, le=2**32 - 1)
