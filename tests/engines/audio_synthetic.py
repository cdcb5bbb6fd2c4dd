"""Synthetic recordings with known beats, for the beat tracker's tests and ``bench/music.py``.

A beat grid whose tempo glides from ``bpm0`` to ``bpm1`` (the beat period follows the tempo at
each beat), played by a small drum kit: a pitched-down kick on every beat (the bar's first beat
louder), a clap of filtered noise on the off-beats of the bar (beats 2 and 4), closed hats on the
eighths, the second eighth of each beat delayed by ``swing`` of a beat period, and white noise at
``snr_db`` below the kit's power.
"""

from __future__ import annotations

import io

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

SR = 22050


def drifting_beats(bpm0: float, bpm1: float, seconds: float, first_s: float = 0.3) -> Array:
    """``(B,)`` beat times (s) of a tempo gliding linearly in time from ``bpm0`` to ``bpm1``."""
    out, t = [], first_s
    while t < seconds - 0.3:
        out.append(t)
        t += 60.0 / (bpm0 + (bpm1 - bpm0) * t / seconds)
    return np.array(out)


def _drum(n: int, rng: np.random.Generator, pitch_hz: float, decay_s: float, noise: float) -> Array:
    t = np.arange(n) / SR
    tone = np.sin(2 * np.pi * np.cumsum(pitch_hz * (1 + 3 * np.exp(-t * 30))) / SR) if pitch_hz else 0.0
    return np.asarray((tone + noise * rng.standard_normal(n)) * np.exp(-t / decay_s))


def drum_track(
    beats: Array, seconds: float, swing: float = 0.0, snr_db: float = 30.0, seed: int = 0, meter: int = 4
) -> Array:
    """Mono samples ``(S,)`` at ``SR`` Hz in [-1, 1] (module doc)."""
    rng = np.random.default_rng(seed)
    y = np.zeros(int(seconds * SR))

    def add(at_s: float, x: Array, gain: float) -> None:
        i = int(at_s * SR)
        x = x[: max(0, y.size - i)]
        y[i : i + x.size] += gain * x

    for k, b in enumerate(beats):
        add(b, _drum(6000, rng, 50.0, 0.1, 0.03), 1.0 if k % meter == 0 else 0.7)
        if k % 2 == 1:
            add(b, _drum(5000, rng, 0.0, 0.05, 1.0), 0.3)
        period = beats[k + 1] - b if k + 1 < beats.size else beats[-1] - beats[-2]
        add(b, _drum(1500, rng, 0.0, 0.01, 1.0), 0.1)
        add(b + period * (0.5 + swing), _drum(1500, rng, 0.0, 0.01, 1.0), 0.07)
    power = float(np.mean(y**2))
    y += rng.standard_normal(y.size) * np.sqrt(power / 10 ** (snr_db / 10))
    return np.asarray(y / np.abs(y).max() * 0.9)


def encode(y: Array, fmt: str = "WAV") -> bytes:
    """The samples as a file in ``fmt`` (soundfile's format name: WAV, FLAC, OGG, MP3)."""
    import soundfile as sf

    buf = io.BytesIO()
    sub = {"WAV": "PCM_16", "FLAC": "PCM_16", "OGG": "VORBIS", "MP3": "MPEG_LAYER_III"}[fmt]
    sf.write(buf, y.astype(np.float32), SR, format=fmt, subtype=sub)
    return buf.getvalue()


def f_measure(found: Array, true: Array, tol_s: float = 0.07) -> float:
    """Beat-tracking F-measure: a found beat within ``tol_s`` of a true beat (each matched once)."""
    found, true = np.asarray(found), np.asarray(true)
    if not found.size or not true.size:
        return 0.0
    used: set[int] = set()
    hits = 0
    for b in true:
        j = int(np.argmin(np.abs(found - b)))
        if abs(found[j] - b) <= tol_s and j not in used:
            used.add(j)
            hits += 1
    p, r = hits / found.size, hits / true.size
    return 2 * p * r / (p + r) if hits else 0.0


BREAK_ONSETS: tuple[tuple[float, float], ...] = (
    (0.058, 1.3), (0.325, 1.97), (0.488, 1.55), (0.65, 2.93), (0.789, 2.7), (1.022, 2.18),
    (1.149, 5.16), (1.44, 0.48), (1.509, 3.16), (1.649, 6.46), (1.834, 5.52), (2.171, 9.52),
    (2.368, 3.02), (2.531, 2.66), (2.705, 2.25),
)  # fmt: skip
"""(time s, strength) of the onsets of a 2.8 s drum-and-bass break at 87.5 BPM (the peaks of
:func:`engines.rhythm.audio.track_beats`' onset envelope on madmom's ``tests/data/audio/sample.wav``,
whose hand-annotated beats are :data:`BREAK_BEATS`): its strongest periodicity is 117 BPM, three
of its eighth notes (the sample itself is not bundled: see tests/engines/test_rhythm_audio_real.py)."""
BREAK_BEATS = np.array([0.0913, 0.7997, 1.4806, 2.1478])
"""The break's beats (s): 87.5 BPM."""


def break_track(seed: int = 0) -> Array:
    """Mono samples ``(S,)`` at ``SR`` Hz: a drum hit at each of :data:`BREAK_ONSETS` (gain = its
    strength), 2.8 s, with noise 40 dB below the peak."""
    rng = np.random.default_rng(seed)
    y = np.zeros(int(2.8 * SR))
    for at_s, gain in BREAK_ONSETS:
        i = int(at_s * SR)
        x = _drum(4000, rng, 60.0, 0.08, 0.5)[: y.size - i]
        y[i : i + x.size] += gain * x
    y += rng.standard_normal(y.size) * 0.01 * np.abs(y).max()
    return np.asarray(y / np.abs(y).max() * 0.9)
