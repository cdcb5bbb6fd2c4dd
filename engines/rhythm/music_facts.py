"""Cheap facts of a request's input files, for its work budget at submission.

Pure functions of the bytes, bounded in time and memory whatever the file holds: a MIDI file's
events are counted by walking its chunks (stopping at :data:`MAX_MIDI_EVENTS`), an audio file's
length is read from its header (``soundfile.info``, no decoding), a BVH's frames and joints from
its header (:func:`motion.bvh_header.bvh_header`). The engines read the same files in full in the
worker; these facts only let :mod:`workers.budget` refuse, at submission, a request whose size
only a parse would reveal.

The MIDI walk is hand-written: mido (what :func:`engines.rhythm.music.parse_midi` uses) builds a
message object per event, 155 s for a file of 2.8M events, and cannot stop after N events.
"""

from __future__ import annotations

import io
import math
import struct
from dataclasses import dataclass, field

MAX_MIDI_EVENTS = 200_000
"""Most events of a MIDI song (a dense ten-minute piano piece has ~100k); past it the file is
refused at submission without being read further."""
MAX_BEATS = 100_000
"""Most music beats of one request (as ``music.beats_s`` allows)."""
MIN_TEMPO_US = 60_000
"""Fastest tempo accepted, microseconds per quarter note (1,000 BPM): faster is not music a body
can dance to, and a 1-us tempo puts millions of beats into a few seconds."""
DEFAULT_TEMPO_US = 500_000
"""The SMF default tempo (120 BPM) before the first set-tempo event."""
MAX_CHANNELS = 64
"""Most channels of a recording (a 7.1.4 mix has 12; a WAV header may claim 65,535, which
decoders misread or choke on): more is refused at submission and by the decoder."""


@dataclass(frozen=True, slots=True)
class MidiFacts:
    """A MIDI file's timing facts. ``events`` counted (at most :data:`MAX_MIDI_EVENTS` + 1);
    ``duration_s`` and ``beats`` (None when the walk stopped early or the file is malformed: the
    engine then reports it); ``problems``: sentences for a work budget (too many events, an
    implausible tempo, too many beats)."""

    events: int
    duration_s: float | None
    beats: int | None
    problems: tuple[str, ...] = field(default=())


def _varlen(data: bytes, pos: int, end: int) -> tuple[int, int]:
    """A MIDI variable-length quantity at ``pos`` (at most 4 bytes): its value and the next byte."""
    value = 0
    for _ in range(4):
        if pos >= end:
            raise IndexError(pos)
        c = data[pos]
        pos += 1
        value = (value << 7) | (c & 0x7F)
        if c < 0x80:
            return value, pos
    raise IndexError(pos)


def _walk_track(
    data: bytes, pos: int, end: int, budget: int, tempos: dict[int, int], sigs: dict[int, int]
) -> tuple[int, int]:
    """Events of one ``MTrk`` body ``[pos, end)`` (at most ``budget + 1``) and its last tick;
    set-tempo events go into ``tempos`` (tick -> us per quarter), time signatures into ``sigs``
    (tick -> beat unit as a fraction of a whole note's denominator). ``IndexError``/``ValueError``
    for malformed data."""
    tick = events = running = 0
    while pos < end and events <= budget:
        delta, pos = _varlen(data, pos, end)
        tick += delta
        status = data[pos]
        if status >= 0x80:
            pos += 1
            if status < 0xF0:
                running = status  # meta and sysex events keep the running status (as mido reads)
        elif running == 0:
            raise ValueError("a data byte without a status byte")
        else:
            status = running
        events += 1
        if status == 0xFF:
            kind = data[pos]
            length, pos = _varlen(data, pos + 1, end)
            if kind == 0x51 and length >= 3:
                tempos[tick] = int.from_bytes(data[pos : pos + 3], "big")
            elif kind == 0x58 and length >= 2:
                sigs[tick] = 2 ** min(data[pos + 1], 6)
            elif kind == 0x2F:
                return events, tick
            pos += length
        elif status in (0xF0, 0xF7):
            length, pos = _varlen(data, pos, end)
            pos += length
        else:
            pos += 1 if status & 0xF0 in (0xC0, 0xD0) else 2
    return events, tick


def _beats(tpq: int, sigs: dict[int, int], end_tick: int) -> int:
    """Beats from tick 0 to ``end_tick`` following the signatures' beat units (as
    :meth:`engines.rhythm.music.TempoMap.beat_ticks` counts them, without the array)."""
    marks = sorted(sigs.items()) or [(0, 4)]
    if marks[0][0] != 0:
        marks.insert(0, (0, 4))
    total = 0
    for i, (tick, den) in enumerate(marks):
        step = tpq * 4.0 / den
        if i + 1 < len(marks):  # np.arange(tick, next - 1e-9, step)
            total += max(0, math.ceil((marks[i + 1][0] - 1e-9 - tick) / step))
        elif end_tick >= tick:  # the last grid, up to the end tick
            total += math.floor((end_tick - tick) / step + 1e-9) + 1
    return total


def _seconds(tpq: int, tempos: dict[int, int], end_tick: int) -> float:
    """Seconds from tick 0 to ``end_tick`` through the tempo map."""
    marks = sorted(tempos.items())
    if not marks or marks[0][0] != 0:
        marks.insert(0, (0, DEFAULT_TEMPO_US))
    seconds = 0.0
    for i, (tick, us) in enumerate(marks):
        if tick >= end_tick:
            break
        stop = min(marks[i + 1][0] if i + 1 < len(marks) else end_tick, end_tick)
        seconds += (stop - tick) * us * 1e-6 / tpq
    return seconds


def midi_facts(data: bytes, max_events: int = MAX_MIDI_EVENTS) -> MidiFacts:
    """Count ``data``'s MIDI events (stopping past ``max_events``) and measure its length and beats.

    Time is linear in the events read (never more than ``max_events + 1``), memory constant. A
    file that is not a readable SMF gives unknown length and no problems: the engine names its
    fault when the job runs."""
    if len(data) < 14 or data[:4] != b"MThd":
        return MidiFacts(0, None, None)
    (hlen,) = struct.unpack(">I", data[4:8])
    _fmt, ntrks, division = struct.unpack(">HHH", data[8:14])
    pos = 8 + hlen
    tempos: dict[int, int] = {}
    sigs: dict[int, int] = {}
    events = end_tick = found = 0
    try:
        while pos + 8 <= len(data) and found < ntrks:
            cid = data[pos : pos + 4]
            (clen,) = struct.unpack(">I", data[pos + 4 : pos + 8])
            body, pos = pos + 8, min(pos + 8 + clen, len(data))
            if cid != b"MTrk":
                continue
            found += 1
            n, tick = _walk_track(data, body, pos, max_events - events, tempos, sigs)
            events += n
            end_tick = max(end_tick, tick)
            if events > max_events:
                return MidiFacts(
                    events,
                    None,
                    None,
                    (f"the MIDI file holds over {max_events} events (the limit; a song has far fewer)",),
                )
    except (IndexError, ValueError):
        return MidiFacts(events, None, None)
    problems = []
    fastest = min(tempos.values(), default=DEFAULT_TEMPO_US)
    if fastest < MIN_TEMPO_US:
        problems.append(
            f"the MIDI file sets a tempo of {fastest} microseconds per quarter note "
            f"({60e6 / max(fastest, 1):.0f} BPM); the fastest accepted is {MIN_TEMPO_US} "
            f"({60e6 / MIN_TEMPO_US:.0f} BPM)"
        )
    if division & 0x8000 or division == 0:  # SMPTE time: beats of the default tempo
        fps_code = 256 - (division >> 8) if division & 0x8000 else 0
        tpf = division & 0xFF
        seconds = end_tick / (fps_code * tpf) if fps_code > 0 and tpf > 0 else None
        beats = None if seconds is None else int(seconds / (DEFAULT_TEMPO_US * 1e-6)) + 1
    else:
        seconds = _seconds(division, tempos, end_tick)
        beats = _beats(division, sigs, end_tick)
    if beats is not None and beats > MAX_BEATS:
        problems.append(f"the MIDI file has {beats} beats, over the limit of {MAX_BEATS}")
    return MidiFacts(events, seconds, beats, tuple(problems))


@dataclass(frozen=True, slots=True)
class AudioFacts:
    """A recording's header: ``frames`` (samples per channel), ``samplerate`` (Hz), ``channels``."""

    frames: int
    samplerate: int
    channels: int

    @property
    def duration_s(self) -> float:
        return self.frames / self.samplerate

    @property
    def decoded_bytes(self) -> int:
        """Bytes the engine holds while decoding (float32 samples of every channel, then mono)."""
        return self.frames * (self.channels + 1) * 4


def audio_facts(data: bytes) -> AudioFacts | None:
    """The header of a WAV, FLAC, Ogg or MP3 recording (``soundfile.info``: no samples decoded),
    None when libsndfile cannot read it (the engine's decoder then tries harder, or says why)."""
    import soundfile as sf

    try:
        info = sf.info(io.BytesIO(data))
    except Exception:  # libsndfile: unsupported or corrupt (RuntimeError, sf.LibsndfileError)
        return None
    if info.samplerate <= 0 or info.frames < 0:
        return None
    return AudioFacts(int(info.frames), int(info.samplerate), max(int(info.channels), 1))


def wav_channels(data: bytes) -> int | None:
    """The channel count a RIFF/WAVE (or RF64) header declares in its ``fmt`` chunk, read from the
    first 64 KiB only; None when ``data`` is not a WAV file or has no readable ``fmt`` chunk."""
    if len(data) < 12 or data[:4] not in (b"RIFF", b"RF64") or data[8:12] != b"WAVE":
        return None
    pos, end = 12, min(len(data), 1 << 16)
    while pos + 8 <= end:
        chunk, size = data[pos : pos + 4], struct.unpack_from("<I", data, pos + 4)[0]
        if chunk == b"fmt ":
            return (
                int(struct.unpack_from("<H", data, pos + 10)[0])
                if size >= 4 and pos + 12 <= len(data)
                else None
            )
        pos += 8 + size + (size & 1)
    return None


def audio_channels(data: bytes) -> int | None:
    """The channel count of a recording: what libsndfile reads from its header, else what a WAV
    header declares (a header libsndfile refuses, e.g. 65,535 channels); None when neither says."""
    facts = audio_facts(data)
    return facts.channels if facts is not None else wav_channels(data)


def channel_problem(channels: int | None) -> str | None:
    """A sentence when a recording has more than :data:`MAX_CHANNELS` channels, else None."""
    if channels is None or channels <= MAX_CHANNELS:
        return None
    return (
        f"audio: the recording has {channels} channels; at most {MAX_CHANNELS} are read "
        "(mix it down to stereo or mono)"
    )
