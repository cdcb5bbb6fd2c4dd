"""Uploaded input files other than clips (e.g. MIDI music for the rhythm engine)."""

from __future__ import annotations

from datetime import datetime

from pydantic import Field

from .common import Strict


class FileInfo(Strict):
    """An uploaded file, stored once per content hash; requests refer to it by id or name."""

    id: str = Field(description="sha256 of the uploaded bytes")
    name: str = Field(description="file name given at upload")
    size_bytes: int
    media_type: str = Field(description="guessed from the content, e.g. 'audio/midi'")
    created_at: datetime
