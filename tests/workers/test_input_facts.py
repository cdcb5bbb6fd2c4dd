"""Input facts for the submission budget: MIDI counted and measured without mido (the same
length and beats as the engine's reader, capped), audio length from the header, a control BVH's
frames from its header, all turned into budget problems."""

from __future__ import annotations

import io
import random
from typing import Any

import mido
import numpy as np
import pytest
import soundfile as sf

from engines.base import DatabaseFacts
from engines.registry import parse_job_request
from engines.rhythm.music import parse_midi
from engines.rhythm.music_facts import MAX_BEATS, audio_facts, midi_facts
from motion.samples import sample_path
from workers.budget import WorkLimits, check_work, estimate_work


def _random_midi(rng: random.Random) -> bytes:
    mf = mido.MidiFile(type=1, ticks_per_beat=rng.choice([1, 7, 96, 480]))
    for _ in range(rng.randint(1, 3)):
        track = mido.MidiTrack()
        mf.tracks.append(track)
        for _ in range(rng.randint(0, 200)):
            r, dt = rng.random(), rng.randint(0, 400)
            if r < 0.05:
                track.append(mido.MetaMessage("set_tempo", tempo=rng.randint(60_000, 2_000_000), time=dt))
            elif r < 0.08:
                num, den = rng.randint(1, 7), rng.choice([2, 4, 8, 16])
                track.append(mido.MetaMessage("time_signature", numerator=num, denominator=den, time=dt))
            elif r < 0.1:
                track.append(mido.Message("sysex", data=[1, 2, 3], time=dt))
            elif r < 0.2:
                track.append(mido.Message("program_change", program=3, time=dt))
            else:
                track.append(mido.Message("note_on", note=60, velocity=rng.randint(0, 100), time=dt))
    buf = io.BytesIO()
    mf.save(file=buf)
    return buf.getvalue()


def test_midi_facts_agree_with_the_engines_reader() -> None:
    rng = random.Random(7)
    files = [sample_path("song").read_bytes()]
    files += [_random_midi(rng) for _ in range(40)]
    for data in files:
        facts, tempo = midi_facts(data), parse_midi(data)
        assert facts.duration_s == pytest.approx(tempo.duration_s(), abs=1e-9)
        assert facts.beats == len(tempo.beat_ticks())
        assert facts.problems == ()


def _smf(track: bytes, division: int = 96) -> bytes:
    header = b"MThd" + (6).to_bytes(4, "big") + bytes([0, 0, 0, 1]) + division.to_bytes(2, "big")
    return header + b"MTrk" + len(track).to_bytes(4, "big") + track


def test_midi_events_are_counted_to_a_cap() -> None:
    track = bytes([0x00, 0x90, 60, 100]) + bytes([0x00, 60, 0]) * 50_000
    facts = midi_facts(_smf(track), max_events=10_000)
    assert facts.events == 10_001 and facts.duration_s is None
    assert "over 10000 events" in facts.problems[0]


def test_an_absurd_tempo_and_its_beats_are_problems() -> None:
    # 36 bytes: 1 us per quarter note, a tick per quarter note, then 2^28 - 1 ticks of nothing
    track = bytes([0x00, 0xFF, 0x51, 3, 0, 0, 1, 0xFF, 0xFF, 0xFF, 0x7F, 0xFF, 0x2F, 0x00])
    facts = midi_facts(_smf(track, division=1))
    assert facts.beats is not None and facts.beats > MAX_BEATS
    assert any("1 microseconds per quarter note" in p for p in facts.problems)
    assert any("beats, over the limit" in p for p in facts.problems)


def test_a_malformed_midi_gives_no_facts_and_no_problems() -> None:
    assert midi_facts(b"not midi") == midi_facts(_smf(bytes([0x00, 60, 0])))  # data byte, no status


def test_audio_facts_come_from_the_header() -> None:
    buf = io.BytesIO()
    sf.write(buf, np.zeros((48_000 * 3, 2), dtype=np.int16), 48_000, format="FLAC")
    facts = audio_facts(buf.getvalue())
    assert facts is not None and facts.duration_s == pytest.approx(3.0)
    assert facts.channels == 2 and facts.decoded_bytes == 48_000 * 3 * 3 * 4
    assert audio_facts(b"RIFF....WAVEjunk") is None


def _rhythm(db_music: dict[str, Any], files: dict[str, bytes], characters: int = 1) -> Any:
    request = parse_job_request(
        {"engine": "rhythm", "database": "d", "music": db_music, "characters": characters}
    )
    request.attach_inputs(files)
    return request


def _facts(fps: float) -> DatabaseFacts:
    return DatabaseFacts(fps, 38, {})


def test_an_hour_of_audio_is_over_budget_whatever_the_dancers() -> None:
    buf = io.BytesIO()
    sf.write(buf, np.zeros((8_000 * 3600, 1), dtype=np.int16), 8_000, format="FLAC")
    hour = buf.getvalue()
    work = estimate_work(_rhythm({"audio": "song.flac"}, {"song.flac": hour}), _facts(120.0))
    assert work.frames == 3600 * 120
    assert any("output frames" in p for p in check_work(work, WorkLimits()))
    crowd = estimate_work(
        _rhythm({"audio": "song.flac", "duration_s": 20}, {"song.flac": hour}, 10_000), _facts(120.0)
    )
    assert crowd.frames == 20 * 120 and crowd.memory_bytes is not None
    assert crowd.memory_bytes > 8_000 * 3600 * 2 * 4  # the whole recording is decoded
    assert any("joint-frames" in p for p in check_work(crowd, WorkLimits()))


def test_midi_problems_reach_the_budget() -> None:
    track = bytes([0x00, 0x90, 60, 100]) + bytes([0x00, 60, 0]) * 250_000
    work = estimate_work(_rhythm({"midi": "long.mid"}, {"long.mid": _smf(track)}), _facts(120.0))
    assert any("events" in p for p in check_work(work, WorkLimits()))


def test_a_control_bvh_counts_its_frames() -> None:
    data = sample_path("salsa-leader").read_bytes()
    request = parse_job_request({"engine": "control", "database": "d", "control": {"bvh": "lead.bvh"}})
    request.attach_inputs({"lead.bvh": data})
    from motion import parse_bvh

    lead = parse_bvh(data)
    work = estimate_work(request, _facts(lead.fps))
    assert work.frames == lead.num_frames
    short = estimate_work(request, _facts(lead.fps))
    assert check_work(short, WorkLimits(max_output_frames=lead.num_frames - 1))


def test_a_control_glb_counts_its_frames() -> None:
    # a glTF control motion (issue 39: a GLB is an input everywhere a BVH is): its first
    # animation's frames, from the accessors' count and range, before the engine runs
    from motion.export.glb import glb_bytes
    from motion.io import load_motion

    lead = load_motion("sample:salsa-leader-05").to_units("m")
    request = parse_job_request({"engine": "control", "database": "d", "control": {"bvh": "lead.glb"}})
    request.attach_inputs({"lead.glb": glb_bytes(lead)})
    assert estimate_work(request, _facts(lead.fps)).frames == lead.num_frames
    assert estimate_work(request, _facts(2 * lead.fps)).frames == 2 * lead.num_frames - 1


def test_an_absurd_channel_count_is_refused_at_submission() -> None:
    """A 65,535-channel WAV (libsndfile refuses its header, so it had no facts and passed) is a
    problem naming the channels; an ordinary recording is none."""
    from engines.rhythm.music_facts import wav_channels

    from ..engines.test_rhythm_audio import _wav_header_claiming

    hostile = _wav_header_claiming(65_535)
    assert wav_channels(hostile) == 65_535
    work = estimate_work(_rhythm({"audio": "many.wav"}, {"many.wav": hostile}), _facts(120.0))
    assert any("65535 channels" in p for p in check_work(work, WorkLimits()))
    buf = io.BytesIO()
    sf.write(buf, np.zeros((8_000, 2), dtype=np.int16), 8_000, format="WAV")
    assert wav_channels(buf.getvalue()) == 2
    ok = estimate_work(_rhythm({"audio": "two.wav"}, {"two.wav": buf.getvalue()}), _facts(120.0))
    assert not any("channels" in p for p in check_work(ok, WorkLimits()))
