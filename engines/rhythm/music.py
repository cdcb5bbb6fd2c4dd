"""Music input for rhythmic synthesis: beat times from a standard MIDI file, a BPM or a beat list.

Standard MIDI Files (SMF formats 0, 1 and 2) are read with mido; the ``MThd`` header and the chunk
layout are checked first (mido reads no SMPTE division and does not say which chunk is short).
Only the timing matters here: set tempo (microseconds per quarter note), time signature and end of
track events are kept; the tempo map of all tracks is merged (format 1 files keep it in track 0,
but a tempo in any track applies to all). Malformed files raise :class:`MusicError` naming the
problem. :func:`write_midi` writes the small test and sample files byte for byte as before.

Beats follow the time signature: the beat unit is the signature's denominator note (a 4/4 bar has
four quarter-note beats, 6/8 six eighth-note beats), 4/4 at 120 BPM when the file gives neither.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

DEFAULT_TEMPO_US = 500_000
"""Microseconds per quarter note when a file sets no tempo (120 BPM, the SMF default)."""


class MusicError(ValueError):
    """Music input that cannot be read (malformed MIDI, too few beats...)."""


@dataclass(frozen=True, slots=True)
class TempoMap:
    """The timing content of a MIDI file.

    Attributes
    ----------
    ticks_per_quarter: ticks per quarter note (metrical division); 0 for SMPTE time.
    seconds_per_tick_smpte: seconds per tick for SMPTE-division files (0 otherwise).
    tempos: ``[(tick, microseconds per quarter note), ...]`` sorted by tick, first at tick 0.
    time_signatures: ``[(tick, numerator, denominator), ...]`` sorted by tick, first at tick 0.
    end_tick: the last event's tick over all tracks (the piece's length).
    """

    ticks_per_quarter: int
    seconds_per_tick_smpte: float
    tempos: list[tuple[int, int]] = field(default_factory=list)
    time_signatures: list[tuple[int, int, int]] = field(default_factory=list)
    end_tick: int = 0

    def tick_to_seconds(self, ticks: npt.ArrayLike) -> Array:
        """Seconds from the start at each tick ``(N,)`` (piecewise-linear through the tempo map)."""
        t = np.asarray(ticks, dtype=np.float64)
        if self.seconds_per_tick_smpte > 0:
            return np.asarray(t * self.seconds_per_tick_smpte)
        starts = np.array([tk for tk, _ in self.tempos], dtype=np.float64)
        sec_per_tick = (
            np.array([us for _, us in self.tempos], dtype=np.float64) * 1e-6 / self.ticks_per_quarter
        )
        seg_seconds = np.diff(starts) * sec_per_tick[:-1]
        offsets = np.concatenate(([0.0], np.cumsum(seg_seconds)))
        k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
        return np.asarray(offsets[k] + (t - starts[k]) * sec_per_tick[k])

    def duration_s(self) -> float:
        return float(self.tick_to_seconds(np.array([self.end_tick]))[0])

    def beat_ticks(self) -> Array:
        """Tick of every beat from 0 to the end, following the time signatures' beat units."""
        if self.seconds_per_tick_smpte > 0:
            # no musical time in SMPTE files: beats of the default tempo
            step = DEFAULT_TEMPO_US * 1e-6 / self.seconds_per_tick_smpte
            return np.arange(0.0, self.end_tick + 1e-9, step)
        sigs = self.time_signatures or [(0, 4, 4)]
        out: list[Array] = []
        for i, (tick, _num, den) in enumerate(sigs):
            # a signature change falls on a bar line: the beat grid restarts there
            stop = sigs[i + 1][0] if i + 1 < len(sigs) else self.end_tick + 1
            out.append(np.arange(float(tick), stop - 1e-9, self.ticks_per_quarter * 4.0 / den))
        ticks = np.concatenate(out) if out else np.zeros(0)
        return ticks[ticks <= self.end_tick + 1e-9]

    def beat_times(self) -> Array:
        """``(B,)`` seconds of every beat of the piece, from 0 to its end."""
        return self.tick_to_seconds(self.beat_ticks())

    def meter(self) -> int:
        """Beats per bar of the first time signature (4 when none)."""
        return self.time_signatures[0][1] if self.time_signatures else 4


def parse_midi(data: bytes) -> TempoMap:
    """The tempo map of a Standard MIDI File.

    Raises :class:`MusicError` for anything that is not a well-formed SMF (bad chunk ids, lengths
    past the end of the file, data bytes without a status, truncated events, bad tempo events).
    """
    import mido

    ntrks, tpq, smpte, pos = _midi_header(data)
    found = sum(1 for _ in _track_chunks(data, pos, ntrks))
    if found < ntrks:
        raise MusicError(f"MIDI: the header declares {ntrks} tracks but the file holds {found}")
    try:
        midi = mido.MidiFile(file=io.BytesIO(data))
    except EOFError:
        raise MusicError("MIDI: an event runs past the end of its track") from None
    except IndexError:
        raise MusicError("MIDI: a meta event is too short (a tempo event must have 3 data bytes)") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        text = str(exc)
        if "running status" in text:
            text = "a data byte without a status byte (running status with no status before it)"
        raise MusicError(f"MIDI: {text}") from None
    tempos: dict[int, int] = {}
    sigs: dict[int, tuple[int, int]] = {}
    end_tick = 0
    for number, track in enumerate(midi.tracks):
        tick = 0
        for msg in track:
            tick += int(msg.time)
            if msg.type == "set_tempo":
                if msg.tempo == 0:
                    raise MusicError(f"MIDI: tempo of 0 microseconds per quarter note in track {number}")
                tempos[tick] = int(msg.tempo)
            elif msg.type == "time_signature":
                if msg.denominator > 64:
                    raise MusicError(f"MIDI: time signature denominator {msg.denominator} is out of range")
                if msg.numerator == 0:
                    raise MusicError(f"MIDI: time signature with 0 beats per bar in track {number}")
                sigs[tick] = (int(msg.numerator), int(msg.denominator))
            elif msg.type == "end_of_track":
                break
        end_tick = max(end_tick, tick)
    tempo_list = sorted(tempos.items())
    if not tempo_list or tempo_list[0][0] != 0:
        tempo_list.insert(0, (0, DEFAULT_TEMPO_US))
    sig_list = [(t, n, d) for t, (n, d) in sorted(sigs.items())]
    if sig_list and sig_list[0][0] != 0:
        sig_list.insert(0, (0, 4, 4))
    return TempoMap(tpq, smpte, tempo_list, sig_list, end_tick)


def _midi_header(data: bytes) -> tuple[int, int, float, int]:
    """The ``MThd`` chunk: track count, ticks per quarter note (0 for SMPTE timing), seconds per
    tick in SMPTE timing (0 otherwise; mido reads no SMPTE division), and the byte where the
    chunks after it start."""
    if len(data) < 14 or data[:4] != b"MThd":
        raise MusicError("not a Standard MIDI File: it must start with an 'MThd' header chunk")
    (hlen,) = struct.unpack(">I", data[4:8])
    if hlen < 6 or 8 + hlen > len(data):
        raise MusicError(f"MIDI header chunk has an invalid length {hlen}")
    fmt, ntrks, division = struct.unpack(">HHH", data[8:14])
    if fmt > 2:
        raise MusicError(f"unsupported MIDI format {fmt} (0, 1 or 2)")
    if ntrks == 0:
        raise MusicError("the MIDI file declares no tracks")
    if division & 0x8000:
        fps_code = -struct.unpack(">b", bytes([division >> 8]))[0]
        tpf = division & 0xFF
        frames = 29.97 if fps_code == 29 else float(fps_code)
        if frames <= 0 or tpf == 0:
            raise MusicError("MIDI SMPTE division is invalid")
        return ntrks, 0, 1.0 / (frames * tpf), 8 + hlen
    if division == 0:
        raise MusicError("MIDI division (ticks per quarter note) is 0")
    return ntrks, division, 0.0, 8 + hlen


def _track_chunks(data: bytes, pos: int, ntrks: int) -> Iterator[tuple[int, int]]:
    """``(first byte, end)`` of the first ``ntrks`` ``MTrk`` chunks from byte ``pos`` on (unknown
    chunks are skipped, as the standard asks), naming a chunk that claims bytes past the end."""
    found = 0
    while pos < len(data) and found < ntrks:
        if pos + 8 > len(data):
            raise MusicError(f"MIDI: truncated chunk header at byte {pos}")
        cid = data[pos : pos + 4]
        (clen,) = struct.unpack(">I", data[pos + 4 : pos + 8])
        body, end = pos + 8, pos + 8 + clen
        if end > len(data):
            raise MusicError(
                f"MIDI: chunk {cid!r} at byte {pos} claims {clen} bytes past the end of the file"
            )
        pos = end
        if cid == b"MTrk":
            found += 1
            yield body, end


def bpm_beats(bpm: float, duration_s: float, offset_s: float = 0.0) -> Array:
    """``(B,)`` beat times ``offset + k * 60 / bpm`` up to ``duration_s`` seconds (inclusive)."""
    if not (bpm > 0 and duration_s > 0):
        raise MusicError("bpm and duration_s must be positive")
    period = 60.0 / bpm
    return np.asarray(
        offset_s + np.arange(int(np.floor((duration_s - offset_s) / period + 1e-9)) + 1) * period
    )


def write_midi(
    tempos: list[tuple[int, float]],
    end_tick: int,
    ticks_per_quarter: int = 480,
    time_signature: tuple[int, int] = (4, 4),
) -> bytes:
    """A format-0 Standard MIDI File with the given tempo changes ``[(tick, bpm), ...]``, a time
    signature, one note per quarter note and an end of track at ``end_tick`` (tests, examples)."""
    events: list[tuple[int, bytes]] = []
    num, den = time_signature
    events.append((0, bytes([0xFF, 0x58, 4, num, int(np.log2(den)), 24, 8])))
    for tick, bpm in tempos:
        us = int(round(60_000_000 / bpm))
        events.append((tick, bytes([0xFF, 0x51, 3]) + us.to_bytes(3, "big")))
    for tick in range(0, end_tick, ticks_per_quarter):
        events.append((tick, bytes([0x90, 60, 100])))
        events.append((tick + ticks_per_quarter // 2, bytes([0x80, 60, 0])))
    events.sort(key=lambda e: e[0])
    track = bytearray()
    last = 0
    for tick, ev in [*events, (end_tick, bytes([0xFF, 0x2F, 0]))]:
        delta = tick - last
        last = tick
        var = [delta & 0x7F]
        delta >>= 7
        while delta:
            var.append((delta & 0x7F) | 0x80)
            delta >>= 7
        track += bytes(reversed(var)) + ev
    header = b"MThd" + struct.pack(">IHHH", 6, 0, 1, ticks_per_quarter)
    return header + b"MTrk" + struct.pack(">I", len(track)) + bytes(track)
