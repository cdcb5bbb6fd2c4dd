"""Music beats of a recording file for the CLI's ``segue beats SONG.wav`` (the service reaches
engines only through the registry, so the file is read and analysed here, as a job would)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from engines.rhythm.audio import audio_beats
from engines.rhythm.music import MusicError

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
        found = audio_beats(data, tempo_bpm)
    except MusicError as exc:
        raise InputError(f"{path}: {exc}") from None
    return {
        "file": str(path),
        "duration_s": round(found.duration_s, 6),
        "tempo_bpm": round(found.tempo_bpm, 4),
        "tempo_confidence": found.tempo_confidence,
        "beats_s": [round(float(t), 6) for t in found.beats_s],
        "downbeat_s": None if found.downbeat is None else round(float(found.beats_s[found.downbeat]), 6),
    }
