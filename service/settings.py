"""Service settings from the environment (``SEGUE_*``), pydantic-settings style.

``get_settings()`` reads the environment once per process; tests build a :class:`Settings` directly
and pass it to :func:`service.app.create_app` (or override :func:`service.deps.app_settings`).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from motion.bvh import DEFAULT_MAX_FRAMES, DEFAULT_MAX_JOINTS, BvhLimits

MiB = 1 << 20


class Settings(BaseSettings):
    """Everything the service reads from its environment (each field is ``SEGUE_<NAME>``)."""

    model_config = SettingsConfigDict(env_prefix="SEGUE_", extra="ignore", frozen=True)

    data_dir: Path = Field(default=Path("./segue-data"), description="the store's root directory")
    redis_url: str | None = Field(default=None, description="Redis job backend; unset = embedded pool")
    workers: int = Field(default=2, ge=1, le=256, description="embedded backend: worker processes")
    api_tokens: Annotated[tuple[str, ...], NoDecode] = Field(
        default=(), repr=False, description="comma-separated bearer tokens; empty = no auth"
    )
    max_upload_bytes: int = Field(default=64 * MiB, ge=1, description="largest accepted clip upload")
    max_bvh_bytes: int = Field(
        default=512 * MiB, ge=1, description="largest BVH text after gunzip (a gzip bomb stops here)"
    )
    max_frames: int = Field(default=DEFAULT_MAX_FRAMES, ge=1, description="most frames in one clip")
    max_joints: int = Field(default=DEFAULT_MAX_JOINTS, ge=1, description="most joints in one clip")
    engine_plugins: str | None = Field(
        default=None, description="comma-separated plugin modules (engines.registry.load_plugins)"
    )
    ws_queue: int = Field(default=64, ge=2, le=100_000, description="per-WebSocket event queue bound")

    @field_validator("api_tokens", mode="before")
    @classmethod
    def _split_tokens(cls, value: Any) -> Any:
        """Accept ``"a,b"`` (the environment form) as well as a sequence."""
        if isinstance(value, str):
            return tuple(t.strip() for t in value.split(",") if t.strip())
        return value

    @property
    def auth_enabled(self) -> bool:
        """True when writes and WebSockets need a bearer token."""
        return bool(self.api_tokens)

    @property
    def bvh_limits(self) -> BvhLimits:
        """The reader limits for uploaded clips."""
        return BvhLimits(max_joints=self.max_joints, max_frames=self.max_frames, max_bytes=self.max_bvh_bytes)


@lru_cache
def get_settings() -> Settings:
    """The settings of this process, read from the environment once."""
    return Settings()
