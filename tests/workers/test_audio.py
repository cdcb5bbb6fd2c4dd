"""``segue beats`` on recordings (workers/audio.py): beats as JSON data, errors naming the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.engines.audio_synthetic import drifting_beats, drum_track, encode, f_measure
from workers.audio import recording_beats
from workers.inputs import InputError


def test_recording_beats_of_a_file(tmp_path: Path) -> None:
    beats = drifting_beats(100.0, 110.0, 10.0)
    path = tmp_path / "song.flac"
    path.write_bytes(encode(drum_track(beats, 10.0, seed=4), "FLAC"))
    info = recording_beats(path)
    assert set(info) == {"file", "duration_s", "tempo_bpm", "tempo_confidence", "beats_s", "downbeat_s"}
    assert 0.5 < info["tempo_confidence"] <= 1.0
    assert f_measure(np.array(info["beats_s"]), beats[beats > 1.0]) >= 0.85
    assert 100 <= info["tempo_bpm"] <= 110


def test_recording_errors_name_the_file(tmp_path: Path) -> None:
    junk = tmp_path / "junk.mp3"
    junk.write_bytes(b"not audio")
    with pytest.raises(InputError, match="junk.mp3: audio: not a WAV"):
        recording_beats(junk)
    with pytest.raises(InputError, match="missing.wav"):
        recording_beats(tmp_path / "missing.wav")
