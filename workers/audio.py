"""Music beats of a recording file for the CLI's ``segue beats SONG.wav``: the file is read here
(size-limited) and analysed by the engine that reads music (:func:`engines.registry.recording_beats`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from engines.base import EngineError
from engines.registry import recording_beats as analyse

from .inputs import MAX_INPUT_BYTES, InputError


def recording_beats(path: Path, tempo_bpm: float | None = None) -> dict[str, Any]:
    """``{"file", "duration_s", "tempo_bpm", "tempo_confidence", "beats_s", "downbeat_s"}`` of the
    recording at ``path`` (seconds; ``downbeat_s`` None when no downbeat is clear;
    ``tempo_confidence`` in [0, 1], how clearly the onsets pick this metrical level over the others,
    0.5 = another is as likely, None when ``tempo_bpm`` was given). Raises :class:`InputError` naming the
    file and the problem (unreadable, too large, silent, longer than an hour, no beat)."""
    try:
        size = path.stat().st_size
        if size > MAX_INPUT_BYTES:
            raise InputError(f"{path} is {size} bytes (limit {MAX_INPUT_BYTES})")
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror or exc}") from None
    try:
        found = analyse(data, tempo_bpm)
    except EngineError as exc:
        raise InputError(f"{path}: {exc}") from None
    return {"file": str(path), **found}
