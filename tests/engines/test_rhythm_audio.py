"""Music beats from recordings (engines/rhythm/audio.py) and recordings as a request's music."""

from __future__ import annotations

import io
import wave

import numpy as np
import pytest

from engines.base import EngineError
from engines.rhythm.audio import MAX_SECONDS, SR, audio_beats, audio_media_type, decode
from engines.rhythm.engine import _on_the_bar, music_beats
from engines.rhythm.music import MusicError
from schemas.rhythm import RhythmRequest

from .audio_synthetic import BREAK_BEATS, break_track, drifting_beats, drum_track, encode, f_measure


def _wav(samples: np.ndarray, rate: int = SR) -> bytes:
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes((np.clip(samples, -1, 1) * 32767).astype("<i2").tobytes())
    return buf.getvalue()


@pytest.fixture(scope="module")
def drifting() -> tuple[np.ndarray, np.ndarray]:
    beats = drifting_beats(96.0, 116.0, 12.0)
    return beats, drum_track(beats, 12.0, swing=0.1, snr_db=20.0, seed=1)


@pytest.mark.parametrize("fmt", ["WAV", "FLAC", "OGG", "MP3"])
def test_every_format_finds_the_drifting_beats(fmt: str, drifting: tuple[np.ndarray, np.ndarray]) -> None:
    beats, y = drifting
    found = audio_beats(encode(y, fmt))
    inner = beats[beats > 1.0]
    assert f_measure(found.beats_s[found.beats_s > 1.0], inner) >= 0.9
    assert 96 <= found.tempo_bpm <= 116
    assert found.duration_s == pytest.approx(12.0, abs=0.1)


def test_downbeat_is_the_louder_kick(drifting: tuple[np.ndarray, np.ndarray]) -> None:
    beats, y = drifting
    found = audio_beats(encode(y, "WAV"))
    assert found.downbeat is not None
    true_index = int(np.argmin(np.abs(beats - found.beats_s[found.downbeat])))
    assert true_index % 4 == 0  # drum_track's bar starts on beats 0, 4, 8...


def test_even_kicks_claim_no_downbeat() -> None:
    beats = drifting_beats(110.0, 110.0, 10.0)
    y = drum_track(beats, 10.0, seed=2, meter=1)  # every kick equally loud
    assert audio_beats(_wav(y)).downbeat is None


def test_tempo_hint_chooses_the_octave() -> None:
    beats = drifting_beats(130.0, 130.0, 10.0)
    y = drum_track(beats, 10.0, seed=3)
    assert audio_beats(_wav(y), tempo_bpm=65.0).tempo_bpm == pytest.approx(65.0, rel=0.05)
    assert audio_beats(_wav(y), tempo_bpm=130.0).tempo_bpm == pytest.approx(130.0, rel=0.05)


def test_the_metrical_level_comes_from_the_onsets_not_the_prior() -> None:
    """A drum-and-bass break at 87.5 BPM whose strongest periodicity is 117 BPM (three eighth notes,
    near the 115 BPM prior): the beat level divides in two, 117 BPM does not, so the beats are found
    at 87.5 BPM (the prior alone gave 120 BPM, F 0.25)."""
    found = audio_beats(encode(break_track()))
    assert f_measure(found.beats_s, BREAK_BEATS) >= 0.75
    assert 80 <= found.tempo_bpm <= 95
    assert found.tempo_confidence is not None and 0.5 < found.tempo_confidence <= 1.0


def test_a_clear_beat_keeps_the_prior_level_with_high_confidence(
    drifting: tuple[np.ndarray, np.ndarray],
) -> None:
    beats, y = drifting
    found = audio_beats(encode(y, "WAV"))
    assert found.tempo_confidence is not None and found.tempo_confidence > 0.6
    assert audio_beats(encode(y, "WAV"), tempo_bpm=105.0).tempo_confidence is None  # a hint decides


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"RIFF\x00\x00\x00\x00WAVEjunkjunk" + bytes(100), "cannot decode"),
        (b"hello, not audio at all", "not a WAV, FLAC, Ogg or MP3"),
        (_wav(np.zeros(SR * 3)), "silent"),
        (_wav(np.sin(np.arange(SR * 5) * 2 * np.pi * 220 / SR) * 0.3), "no detectable beat"),
        (_wav(np.full(int(MAX_SECONDS) + 60, 0.1), rate=1), "limit is one hour"),
    ],
)
def test_bad_recordings_are_clear_errors(data: bytes, message: str) -> None:
    with pytest.raises(MusicError, match=message):
        audio_beats(data)


def test_media_types_from_magic_bytes() -> None:
    assert audio_media_type(b"RIFF\x00\x00\x00\x00WAVEfmt ") == "audio/wav"
    assert audio_media_type(b"fLaC\x00") == "audio/flac"
    assert audio_media_type(b"OggS\x00") == "audio/ogg"
    assert audio_media_type(b"ID3\x04") == "audio/mpeg"
    assert audio_media_type(b"\xff\xfb\x90") == "audio/mpeg"
    assert audio_media_type(b"MThd\x00") is None


def test_decode_mixes_to_mono_and_resamples() -> None:
    import soundfile as sf

    buf = io.BytesIO()
    t = np.arange(44100) / 44100
    tone = np.sin(2 * np.pi * 440 * t)
    sf.write(buf, np.stack((tone, -0.5 * tone), 1), 44100, format="WAV")
    y, seconds = decode(buf.getvalue())
    assert seconds == pytest.approx(1.0)
    assert y.size == pytest.approx(SR, abs=2)
    assert np.abs(y).max() == pytest.approx(0.25, abs=0.02)


def test_request_with_a_recording(drifting: tuple[np.ndarray, np.ndarray]) -> None:
    beats, y = drifting
    r = RhythmRequest.model_validate({"music": {"audio": "song.ogg", "tempo_bpm": 105}})
    assert r.input_files() == ["song.ogg"] and r.audio_inputs() == ["song.ogg"]
    r.attach_inputs({"song.ogg": encode(y, "OGG")})
    got = music_beats(r, beats_per_movement=4)
    assert f_measure(got[got > 1.0], beats[beats > 1.0]) >= 0.9
    silent = RhythmRequest.model_validate({"music": {"audio": "quiet.wav"}})
    silent.attach_inputs({"quiet.wav": _wav(np.zeros(SR))})
    with pytest.raises(EngineError, match="silent"):
        music_beats(silent)


@pytest.mark.parametrize(
    ("music", "message"),
    [
        ({"audio": "song.mid"}, r"\.wav, \.flac"),
        ({"midi": "song.mid", "tempo_bpm": 100}, "hint for 'audio'"),
        ({"audio": "a.wav", "bpm": 100, "duration_s": 4}, "exactly one"),
    ],
)
def test_request_audio_validation(music: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        RhythmRequest.model_validate({"music": music})


def test_movements_start_on_the_downbeat() -> None:
    beats = 1.0 + 0.5 * np.arange(12)
    shifted = _on_the_bar(beats, 3, 4)  # downbeat at beat 3: one beat before 1.0 s completes a movement
    np.testing.assert_allclose(shifted[:2], [0.5, 1.0])
    assert shifted[4] == beats[3]  # the second movement starts on the downbeat
    early = 0.2 + 0.5 * np.arange(12)  # three beats before 0.2 s would be before 0 s: one is dropped
    np.testing.assert_allclose(_on_the_bar(early, 1, 4), early[1:])
    np.testing.assert_allclose(_on_the_bar(beats, None, 4), beats)
    np.testing.assert_allclose(_on_the_bar(beats, 4, 4), beats)


def _wav_header_claiming(channels: int, frames: int = 400, rate: int = 8000) -> bytes:
    """A PCM WAV whose ``fmt`` chunk declares ``channels`` channels (16-bit samples that are not
    all zero), as a hostile upload would send it."""
    import struct

    data = b"\x00\x10" * channels * frames
    fmt = struct.pack("<HHIIHH", 1, channels, rate, rate * channels * 2, (channels * 2) & 0xFFFF, 16)
    body = b"WAVEfmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", len(data)) + data
    return b"RIFF" + struct.pack("<I", len(body)) + body


def test_an_absurd_channel_count_is_a_clear_error() -> None:
    """A WAV header claiming 65,535 channels was decoded into garbage (or failed with a raw
    ValueError further on); it is a MusicError naming the count and the limit."""
    with pytest.raises(MusicError, match="65535 channels; at most 64"):
        decode(_wav_header_claiming(65_535))
    y, _ = decode(_wav_header_claiming(2, frames=8000))  # an ordinary header still decodes
    assert y.size > 0
